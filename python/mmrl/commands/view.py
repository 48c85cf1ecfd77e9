"""``mmrl view`` and ``mmrl play``: the browser viewer (``mmrl[viewer]``, see docs/viewer.md).

- ``mmrl view SOURCE``: play back a run's episodes, a BVH file or a database's clips;
- ``mmrl play RUN``: the run's policy live on the full path, steered by clicks.

Both serve on 127.0.0.1 (``--host`` opens the viewer to others, with a warning); a busy
port is replaced by the next free one, and the address is printed.
"""
from __future__ import annotations

import argparse
import signal
import threading
import webbrowser

from .common import (add_data_options, add_deploy_set, deploy_config, deprecated_alias, output_path, port,
                     positive_float, run_database, seed)


def _server_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--port", type=port, default=8080, help="port to serve on (default: 8080; the next free one if "
                   "busy; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default: 127.0.0.1, this machine only; 0.0.0.0 opens it to the network)")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser tab")


def register_cli(sub) -> None:
    v = sub.add_parser("view", help="watch a run's episodes, a BVH file or a database's clips in the browser")
    v.add_argument("source", metavar="SOURCE", help="a training run directory, a .bvh file or a database .npz")
    _server_options(v)
    v.add_argument("--length", type=positive_float, default=20.0, metavar="SECONDS",
                   help="run: seconds of episodes to play (default: 20)")
    deprecated_alias(v, "--seconds", "--length (--seconds is a training budget)", "length", type=positive_float)
    v.add_argument("--seed", type=seed, default=0, help="run: random seed of the episodes (default: 0)")
    v.add_argument("--stage", type=int, default=None, metavar="K",
                   help="run: curriculum stage (default: the last)")
    v.set_defaults(func=cmd_view)

    p = sub.add_parser("play", help="steer a trained policy live in the browser (click the ground to set the target)")
    p.add_argument("run", metavar="RUN", help="a training run directory")
    add_data_options(p)
    _server_options(p)
    p.add_argument("--policy", choices=("trained", "joystick", "joystick-run"), default="trained",
                   help="the policy to start with (switchable in the page; default: trained)")
    p.add_argument("--trace", metavar="FILE", help="append one JSON line per decision step to FILE")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the start (and obstacles) (default: 0)")
    p.add_argument("--stage", type=int, default=None, metavar="K", help="curriculum stage (default: the last)")
    p.add_argument("--request", default="", metavar="TAGS",
                   help="the request to start with, e.g. \"style=elderly\" (switchable in the page; docs/styles.md)")
    p.add_argument("--compressed", default=None, metavar="FILE",
                   help="play a compressed controller (mmrl compress) instead of the database (docs/compressed.md)")
    add_deploy_set(p)
    p.set_defaults(func=cmd_play)


def _serve(args, title: str):
    from ..viewer.scene import Scene

    scene = Scene(args.host, args.port, title=title)
    if args.port not in (0, scene.port):
        print(f"port {args.port} is busy; using {scene.port}", flush=True)
    return scene


def _wait(scene, app_run, args) -> int:
    """Run ``app_run(stop)`` in the foreground until Ctrl+C; then stop the server."""
    print(f"serving {scene.url} (Ctrl+C to stop)", flush=True)
    if not args.no_browser:
        threading.Timer(0.5, webbrowser.open, (scene.url,)).start()
    stop = threading.Event()
    # SIGTERM (a test harness, `timeout`, a service manager) stops as Ctrl+C does: cleanly, with the report.
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        app_run(stop)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        stop.set()
        scene.close()
    return 0


def _interrupt(_signum, _frame):
    raise KeyboardInterrupt


def cmd_view(args: argparse.Namespace) -> int:
    from ..viewer.clips import load_playback
    from ..viewer.view_app import ViewApp

    playback = load_playback(args.source, seconds=args.length, seed=args.seed, stage=args.stage)
    scene = _serve(args, f"mmrl view {playback.name}")
    app = ViewApp(scene, playback)
    return _wait(scene, app.run, args)


def cmd_play(args: argparse.Namespace) -> int:
    from ..runs import RunDir
    from .run import _check_stage
    from ..viewer.live import LiveSession
    from ..viewer.play_app import PlayApp

    import torch

    # One observation per decision: a second torch thread only adds hand-off and contention
    # (the obstacles CNN: 0.5 ms on one thread, 25 ms on two while another process trains).
    torch.set_num_threads(1)
    run = RunDir(args.run, require_run=True)
    task = run.task
    _check_stage(task, args.stage)
    from .run import check_request, compressed_model

    db = run_database(run, args)
    if args.trace:
        output_path(args.trace, "--trace")
    compressed = compressed_model(args, db, args.request)
    config = deploy_config(task, run.task_config(task), args.set, db)
    session = LiveSession(task, db, run.policy(), config=config, stage=args.stage,
                          seed=args.seed, trace=args.trace, request=check_request(db, args.request),
                          compressed=compressed)
    session.policy_name = args.policy
    scene = _serve(args, f"mmrl play {run.path.name}")
    app = PlayApp(scene, session)
    try:
        return _wait(scene, app.run, args)
    finally:
        session.close()
        print(app.timing_report(), flush=True)
