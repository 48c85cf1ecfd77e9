"""The moving-obstacles goals (issue 24): stage-10 success and motion quality of trained runs next
to the joysticks with and without the collision-aware search, all on the same episodes.

    python bench/bench_obstacles_goals.py RUN [RUN ...] [--db FILE.npz] [--episodes 2000]
        [--quality-episodes 200] [--seed 1000] [--peers joystick joystick+path ...]
        [--peer-cost C] [--peer-speeds V ...] [--json OUT.json]

Success comes from ``--episodes`` fast-path episodes (``mmrl.rollout.evaluate_fast``, the same
episodes for every controller); motion from ``--quality-episodes`` full-path episodes
(``evaluate_full_path``, IK on, with the IK-off foot sliding of the same run), plus the
raw-mocap floor. Peers (``--peers``):

- ``joystick`` / ``joystick-run``: straight at the target at walking / running speed, blind;
- ``joystick+path`` / ``joystick-run+path``: the same queries through the collision-aware
  search (``path_filter``, the task's defaults: the 16 nearest re-ranked);
- ``joystick+path-exact`` / ``joystick-run+path-exact``: the exact filtered search over the
  whole database (``path_candidates=0``), slow in crowds (tens of ms per decision);
  ``--peer-cost`` sets its path cost;
- ``joystick+deployed`` / ``joystick-run+deployed``: the same queries through the first RUN's own
  options (its deployed search: the ``mmrl`` preset's escapes and path cost, its transition
  cost): the non-learned controller at the policy's own search and budget.

A peer walks at its preset's speed (``database_speeds``: the data's walking or running speed;
LAFAN1 0.93 and 2.51 m/s, Bandai-Namco 1.15 and 2.76), or at each of ``--peer-speeds``.

Each RUN runs with its own options (its config.json), and once more per ``--set`` with those
changed (e.g. ``--set transition_cost=30`` or ``--set path_escapes=20,path_cost=10000``). Prints a
markdown table.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

PEERS = ("joystick", "joystick-run", "joystick+path", "joystick-run+path", "joystick+path-exact",
         "joystick-run+path-exact", "joystick+deployed", "joystick-run+deployed")
KEYS = ("foot_sliding_ik_off_cm_per_s", "foot_sliding_cm_per_s", "transitions_per_s", "pose_jump_p99_cm")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="*", help="training run directories")
    ap.add_argument("--db", default=None, help="database .npz (default: the first run's)")
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--quality-episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--peers", nargs="*", default=["joystick", "joystick+path"], choices=PEERS)
    ap.add_argument("--peer-cost", type=float, default=100.0, help="path_cost of the peers with the filter")
    ap.add_argument("--peer-speeds", type=float, nargs="*", default=None, metavar="M_PER_S",
                    help="run each peer at these speeds (m/s) instead of its preset's (the data's walking or "
                         "running speed, mmrl.rl.policies.database_speeds)")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="also run each RUN with these task options changed (one extra row per --set, "
                    "several options separated by commas)")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from mmrl.motion.database import Database
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import evaluate_fast, evaluate_full_path
    from mmrl.runs import RunDir
    from mmrl.tasks import get_task

    task = get_task("obstacles")
    runs = [RunDir(r) for r in args.runs]
    if args.db:
        db = Database.load(args.db)
    elif runs:
        db = runs[0].database()
    else:
        ap.error("give a RUN or --db")
    controllers = []
    for peer in args.peers:
        name, _, search = peer.partition("+")
        cfg = task.default_config()
        if search == "deployed":
            if not runs:
                ap.error(f"--peers {peer}: give a RUN (the peer takes its options)")
            cfg = runs[0].task_config(task)
        elif search:
            cfg = cfg.replace(path_filter=True, path_cost=args.peer_cost,
                              path_candidates=0 if search == "path-exact" else cfg.path_candidates)
        if args.peer_speeds:
            controllers += [(f"{peer} at {v:g} m/s", JoystickPolicy(db, v), cfg) for v in args.peer_speeds]
        else:
            controllers.append((peer, JoystickPolicy.preset(db, name), cfg))
    from mmrl.commands.common import split_overrides

    for run, path in zip(runs, args.runs):
        policy, cfg = run.policy(), run.task_config(task)
        controllers.append((path, policy, cfg))
        for item in args.set:
            (values,) = split_overrides(item.split(","), cfg)
            controllers.append((f"{path} ({item})", policy, cfg.replace(**values)))

    results = {}
    floor = None
    for name, policy, cfg in controllers:
        t0 = time.perf_counter()
        fast = evaluate_fast(task, db, policy, episodes=args.episodes, seed=args.seed, config=cfg,
                             num_threads=args.threads)
        t1 = time.perf_counter()
        row = {"success_rate": fast["success_rate"], "success_stderr": fast["success_stderr"],
               "collision_rate": fast.get("collision_rate"), "fast_s": t1 - t0}
        if args.quality_episodes > 0:
            on = evaluate_full_path(task, db, policy, episodes=args.quality_episodes, seed=args.seed, config=cfg)
            row.update({k: on.get(k) for k in KEYS})
            row["full_path_success_rate"] = on["success_rate"]
            floor = floor or on.get("raw_mocap")
        row["seconds"] = time.perf_counter() - t0
        results[name] = row
        print(f"{name}: {json.dumps(row)}", flush=True)

    print()
    print("| controller | stage-10 success | transitions/s | sliding IK off (cm/s) | sliding IK on (cm/s) | "
          "pose-jump p99 (cm) |")
    print("|---|---:|---:|---:|---:|---:|")

    def fmt(v, spec=".2f"):
        return "" if v is None else format(v, spec)

    for name, r in results.items():
        print(f"| {name} | {100 * r['success_rate']:.1f}% ± {100 * r['success_stderr']:.1f} | "
              f"{fmt(r.get('transitions_per_s'))} | {fmt(r.get('foot_sliding_ik_off_cm_per_s'), '.1f')} | "
              f"{fmt(r.get('foot_sliding_cm_per_s'))} | {fmt(r.get('pose_jump_p99_cm'), '.1f')} |")
    if floor:
        print(f"| raw mocap (floor) | | | {fmt(floor.get('foot_sliding_ik_off_cm_per_s') or floor.get('foot_sliding_cm_per_s'), '.1f')} | | |")
    if args.json:
        Path(args.json).write_text(json.dumps({"episodes": args.episodes, "quality_episodes": args.quality_episodes,
                                               "seed": args.seed, "results": results, "raw_mocap": floor},
                                              indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
