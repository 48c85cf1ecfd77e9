"""``mmrl eval``, ``mmrl render`` and ``mmrl export-bvh``: run a policy on the full-path controller.

They share their options: an optional training run directory (its ``latest.pt`` policy and
its ``config.json`` database), ``--data``/``--db``, ``--env``, ``--policy``, ``--seed``,
``--seconds``, ``--episodes``, ``--stage``, ``--no-ik`` and ``--no-inertialization``.

``--env obstacles`` (the default for a run trained with ``mmrl train obstacles``) steps the
moving-obstacles env and the full-path character side by side
(:mod:`mmrl.obstacle_rollouts`), at curriculum stage ``--stage`` (default: the last).
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
from pathlib import Path
from typing import Any, Dict, Optional

import numpy as np

POLICIES = ("joystick", "joystick-run")
ENVS = ("plane", "obstacles")
#: Curriculum stages of the moving-obstacles task (mmrl.obstacles.Curriculum's default).
NUM_STAGES = 10


def add_shared_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", nargs="?", metavar="RUN",
                   help="a training run directory (uses RUN/latest.pt and the database named in RUN/config.json)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--data", nargs="+", metavar="DIR|FILE", help="BVH files or directories to build the database from")
    src.add_argument("--db", metavar="FILE", help="a database saved by 'mmrl db build'")
    p.add_argument("--env", choices=ENVS, default=None,
                   help="the task (default: RUN's task if RUN is given, else plane)")
    p.add_argument("--stage", type=int, default=None, metavar="K",
                   help=f"obstacles: curriculum stage 1..{NUM_STAGES} (default: {NUM_STAGES}, the hardest)")
    p.add_argument("--policy", choices=POLICIES, default=None,
                   help="a scripted policy (default: RUN's trained policy if RUN is given, else joystick)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    p.add_argument("--seconds", type=float, default=10.0, help="length of rendered/exported motion (default: 10)")
    p.add_argument("--episodes", type=int, default=20, help="evaluation episodes (default: 20)")
    p.add_argument("--no-ik", action="store_true", help="switch off foot locking and leg IK")
    p.add_argument("--no-inertialization", action="store_true", help="hard switches at transitions")


def register_cli(sub) -> None:
    e = sub.add_parser("eval", help="evaluate a policy on the task with the full character (quality metrics)")
    add_shared_options(e)
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.set_defaults(func=cmd_eval)

    r = sub.add_parser("render", help="render a policy following a sequence of targets to MP4 or GIF")
    add_shared_options(r)
    r.add_argument("-o", "--output", required=True, help="output .mp4 or .gif")
    r.add_argument("--size", default="640x360", help="video size WxH (default: 640x360)")
    r.add_argument("--still", metavar="PNG", help="also write the middle frame as a PNG")
    r.set_defaults(func=cmd_render)

    x = sub.add_parser("export-bvh", help="write generated motion as BVH on the input skeleton (+ .npz of positions)")
    add_shared_options(x)
    x.add_argument("-o", "--output", required=True, help="output .bvh (the .npz is written beside it)")
    x.set_defaults(func=cmd_export)


# ---------------------------------------------------------------------- resolution
def _run_config(run: Optional[str]) -> Dict[str, Any]:
    if run is None:
        return {}
    d = Path(run)
    if not d.is_dir():
        raise FileNotFoundError(f"{d}: no such run directory")
    cfg = d / "config.json"
    if not cfg.is_file():
        return {}
    try:
        return json.loads(cfg.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{cfg}: not valid JSON ({e})") from e


def resolve_database(args: argparse.Namespace):
    from ..envs import resolve_database as resolve

    if args.db or args.data:
        return resolve(db=args.db, data=args.data)
    cfg = _run_config(args.run)
    # 'mmrl train' writes {"data": {"db": FILE} | {"data": [PATHS], "mirror": bool} | {}}.
    spec = cfg.get("data")
    if isinstance(spec, (str, list)):
        spec = {"data": spec}
    spec = spec if isinstance(spec, dict) else {}
    if spec.get("db"):
        return resolve(db=spec["db"])
    if spec.get("data"):
        return resolve(data=spec["data"], mirror=bool(spec.get("mirror", False)))
    return resolve()


def resolve_env(args: argparse.Namespace) -> str:
    """The task: --env, else the run's own, else plane. Also checks --stage against it."""
    saved = _run_config(args.run).get("task")
    if saved is not None and saved not in ENVS:
        raise ValueError(f"{args.run}: unknown task {saved!r} in config.json")
    env = args.env or saved or "plane"
    if saved is not None and args.policy is None and env != saved:
        raise ValueError(f"{args.run} is a '{saved}' run; its policy cannot run --env {env} "
                         f"(pass --env {saved}, or --policy joystick)")
    if args.stage is not None:
        if env != "obstacles":
            raise ValueError("--stage applies to --env obstacles only")
        if not 1 <= args.stage <= NUM_STAGES:
            raise ValueError(f"--stage must be in 1..{NUM_STAGES}, got {args.stage}")
    args.env = env
    return env


def resolve_task_config(args: argparse.Namespace):
    """The task's numbers: the run's own (config.json "task_config") when given, else the defaults."""
    from dataclasses import fields

    if resolve_env(args) == "obstacles":
        from ..obstacles import ObstaclesConfig as Config
    else:
        from ..envs import PlaneConfig as Config

    cfg = Config()
    saved = _run_config(args.run)
    if saved.get("task", args.env) != args.env:  # a scripted policy on another task: the defaults
        return cfg
    names = {f.name for f in fields(Config)}
    for k, v in (saved.get("task_config") or {}).items():
        if k in names:
            setattr(cfg, k, v)
    return cfg


def _stage(args) -> int:
    return NUM_STAGES if args.stage is None else args.stage


def resolve_policy(args: argparse.Namespace, db):
    from ..policies import JoystickPolicy

    if args.policy is not None:
        return JoystickPolicy.preset(db, args.policy), args.policy
    if args.run is not None:
        try:
            ppo = importlib.import_module("mmrl.ppo")
        except ModuleNotFoundError as e:
            raise ValueError("this mmrl has no PPO module (mmrl.ppo) to load the run's policy; "
                             "pass --policy joystick") from e
        path = Path(args.run) / "latest.pt"
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no trained policy in this run directory")
        return ppo.load_policy(path), str(path)
    return JoystickPolicy.preset(db, "joystick"), "joystick"


def _options(args):
    return dict(ik=not args.no_ik, foot_locking=not args.no_ik,
                inertialization_halflife=0.0 if args.no_inertialization else 0.1)


# ---------------------------------------------------------------------- commands
def cmd_eval(args: argparse.Namespace) -> int:
    from ..rollouts import evaluate_full_path

    if args.episodes < 1:
        raise ValueError("--episodes must be >= 1")
    config = resolve_task_config(args)
    db = resolve_database(args)
    policy, name = resolve_policy(args, db)
    t0 = time.perf_counter()
    if args.env == "obstacles":
        from ..obstacle_rollouts import evaluate_obstacles

        res = evaluate_obstacles(db, policy, episodes=args.episodes, seed=args.seed, config=config,
                                 stage=_stage(args), **_options(args))
    else:
        res = evaluate_full_path(db, policy, episodes=args.episodes, seed=args.seed, config=config,
                                 **_options(args))
    res.update({"policy": name, "env": args.env, "seed": args.seed, "ik": not args.no_ik,
                "inertialization": not args.no_inertialization, "wall_time_s": time.perf_counter() - t0})
    if args.json:
        json.dump(res, sys.stdout)
        sys.stdout.write("\n")
    else:
        fmt = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
        where = f" (stage {res['stage']})" if args.env == "obstacles" else ""
        print(f"{name} on {args.env}{where}: {args.episodes} episodes")
        keys = ["success_rate", "mean_time_to_target_s", "foot_sliding_cm_per_s", "max_pose_jump_cm",
                "transitions_per_s"]
        if args.env == "obstacles":
            keys[1:1] = ["collision_rate"]
        for k in keys:
            print(f"  {k:<24} {fmt(res[k])}")
    return 0


def _follow(args):
    from ..rollouts import follow_targets

    if not args.seconds > 0:
        raise ValueError("--seconds must be positive")
    config = resolve_task_config(args)
    db = resolve_database(args)
    policy, _ = resolve_policy(args, db)
    if args.env == "obstacles":
        from ..obstacle_rollouts import follow_obstacles

        return db, follow_obstacles(db, policy, seconds=args.seconds, seed=args.seed, config=config,
                                    stage=_stage(args), **_options(args))
    return db, follow_targets(db, policy, seconds=args.seconds, seed=args.seed, config=config, **_options(args))


def cmd_render(args: argparse.Namespace) -> int:
    from ..metrics import body_joints
    from ..render import render_frame, render_video

    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size expects WxH, got {args.size!r}") from None
    out = Path(args.output)
    if out.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"{out}: the output must end in .mp4 or .gif")
    db, rec = _follow(args)
    obstacles = args.env == "obstacles"
    t0 = time.perf_counter()
    n = render_video(out, rec, db, width=w, height=h, still=args.still if obstacles else None)
    dt = time.perf_counter() - t0
    print(f"wrote {out}: {n} frames ({n / db.fps:.1f} s) rendered in {dt:.2f} s ({n / dt:.0f} frames/s)")
    if obstacles:
        names = {1: "success", 2: "collision", 3: "safety cap"}
        print(f"stage {int(rec['stage'])}, episodes: " +
              ", ".join(names.get(int(o), "running") for o in rec["outcomes"]))
        if args.still:
            print(f"wrote {args.still}")
    elif args.still:
        import imageio.v3 as iio

        t = n // 2
        q = int(np.searchsorted(rec["query_frames"], t, side="right") - 1)
        img = render_frame(rec["positions"][t], db.parents, body_joints=body_joints(db), joint_names=db.joint_names,
                           targets=rec["targets"][t], query_points=rec["query_points"][q],
                           query_directions=rec["query_directions"][q], width=w, height=h)
        iio.imwrite(args.still, img)
        print(f"wrote {args.still}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from .. import _core

    out = Path(args.output)
    if out.suffix.lower() != ".bvh":
        raise ValueError(f"{out}: the output must end in .bvh")
    db, rec = _follow(args)
    motion = _core.motion_from_pose(db._db, np.ascontiguousarray(rec["local_translations"], np.float32),
                                    np.ascontiguousarray(rec["local_rotations"], np.float32), out.name)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(motion.to_bvh())
    npz = out.with_suffix(".npz")
    extra = {}
    if args.env == "obstacles":  # per-frame obstacle corners and the episode index (episodes are cut together)
        extra = {"obstacles": rec["obstacles"], "episode": rec["episode"], "outcomes": rec["outcomes"]}
    np.savez(npz, positions=rec["positions"].astype(np.float32), joint_names=np.array(db.joint_names, np.str_),
             parents=np.array(db.parents, np.int32), fps=np.float32(db.fps), roots=rec["roots"],
             frames=rec["frames"], contacts=rec["contacts"], targets=rec["targets"], **extra)
    print(f"wrote {out} ({motion.num_frames} frames at {db.fps:g} fps) and {npz} (global joint positions, meters)")
    return 0
