"""The arrive goals (issue 38, docs/arrive.md): trained runs next to the arrive joystick, all on the
same full-path episodes, and the motion while standing next to the raw mocap's idle frames.

    python bench/bench_arrive.py RUN [RUN ...] [--data DIR | --db FILE] [--episodes 200]
        [--standing-episodes 50] [--seed 0] [--set KEY=VALUE,...] [--picture PNG] [--json OUT.json]

Per run (its own options, and once more per ``--set``): success, the final position and facing
errors (median and p95 over successes), time to rest, and against the arrive joystick at the
run's own mean speed on the same episodes: the time ratio over the episodes both finished and
their precision there. Motion over the episodes (foot sliding IK on and off, transitions/s,
pose-jump p99), and while standing (``mmrl.eval.standing``: after each success, 3 s more at the
same target and facing): foot sliding IK on and off, transitions/s, pose-jump p99 and the pose
jump at the stop, for the run and for the joystick, next to the raw mocap's idle frames. Prints
a markdown table and each goal's verdict. ``--picture`` draws eight episodes of the first run:
the root's path, the target and its facing (arrow), and where the character stood (its arrow).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

MOTION = ("foot_sliding_cm_per_s", "foot_sliding_ik_off_cm_per_s", "transitions_per_s", "pose_jump_p99_cm")


def _median(values):
    return float(np.median(values)) if len(values) else None


def _both_finished(policy_res, joystick_res):
    """The time ratio and the two controllers' median errors over the episodes both finished."""
    pairs = [(p, j) for p, j in zip(policy_res["episode_results"], joystick_res["episode_results"])
             if p["success"] and j["success"]]
    out = {"both_finished": len(pairs)}
    if pairs:
        out["time_ratio"] = (sum(p["time_to_target_s"] for p, _ in pairs) /
                             sum(j["time_to_target_s"] for _, j in pairs))
        for who, k in (("policy", 0), ("joystick", 1)):
            out[f"{who}_position_cm"] = _median([pair[k]["final_position_error_cm"] for pair in pairs])
            out[f"{who}_facing_deg"] = _median([pair[k]["final_facing_error_deg"] for pair in pairs])
    return out


def measure(task, db, policy, cfg, args):
    from mmrl.eval.standing import evaluate_standing
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import evaluate_full_path

    res = evaluate_full_path(task, db, policy, episodes=args.episodes, seed=args.seed, config=cfg)
    joystick = JoystickPolicy(db, float(res["mean_speed_m_per_s"] or 1.0), arrive=True)
    joy = evaluate_full_path(task, db, joystick, episodes=args.episodes, seed=args.seed, config=cfg)
    row = {"success_rate": res["success_rate"], "time_s": res["mean_time_to_target_s"],
           "speed_m_per_s": res["mean_speed_m_per_s"],
           **{k: res.get(k) for k in res if k.startswith("final_")},
           **{k: res.get(k) for k in MOTION},
           "joystick": {"success_rate": joy["success_rate"], "time_s": joy["mean_time_to_target_s"],
                        **{k: joy.get(k) for k in MOTION}},
           **_both_finished(res, joy)}
    if args.standing_episodes > 0:
        for who, p in (("standing", policy), ("joystick_standing", joystick)):
            st = evaluate_standing(task, db, p, episodes=args.standing_episodes, seed=args.seed, config=cfg)
            st.pop("episode_results")
            row[who] = st
    return row


def verdicts(row) -> list:
    """Each goal of issue 38 against this row: (goal, measured, met)."""
    out = [("success >= 95%", f"{100 * row['success_rate']:.1f}%", row["success_rate"] >= 0.95)]
    pm, pp = row.get("final_position_error_cm_median"), row.get("final_position_error_cm_p95")
    fm, fp = row.get("final_facing_error_deg_median"), row.get("final_facing_error_deg_p95")
    if pm is not None:
        out.append(("position median <= 10 cm, p95 <= 25", f"{pm:.1f} / {pp:.1f} cm", pm <= 10 and pp <= 25))
        out.append(("facing median <= 5 deg, p95 <= 15", f"{fm:.1f} / {fp:.1f} deg", fm <= 5 and fp <= 15))
    if row.get("time_ratio") is not None:
        precise = (row["policy_position_cm"] <= row["joystick_position_cm"]
                   and row["policy_facing_deg"] <= row["joystick_facing_deg"])
        out.append(("time to rest <= 0.9x the arrive joystick's, as precise",
                    f"{row['time_ratio']:.2f}x over {row['both_finished']} episodes both finished; "
                    f"position {row['policy_position_cm']:.1f} vs {row['joystick_position_cm']:.1f} cm, facing "
                    f"{row['policy_facing_deg']:.1f} vs {row['joystick_facing_deg']:.1f} deg",
                    row["time_ratio"] <= 0.9 and precise))
    st = row.get("standing")
    if st and st.get("stood"):
        raw = st["raw_idle"]["foot_sliding_cm_per_s"]
        off, on = st["foot_sliding_ik_off_cm_per_s"], st["foot_sliding_cm_per_s"]
        out.append(("standing: sliding IK off <= 1.2x raw idle", f"{off:.1f} cm/s vs {raw:.1f} ({off / raw:.1f}x)",
                    off <= 1.2 * raw))
        out.append(("standing: sliding IK on <= 1 cm/s", f"{on:.2f} cm/s", on <= 1.0))
        out.append(("standing: <= 0.5 transitions/s", f"{st['transitions_per_s']:.2f}", st["transitions_per_s"] <= 0.5))
    joy = row["joystick"]
    if row.get("pose_jump_p99_cm") is not None and joy.get("pose_jump_p99_cm"):
        ratio = row["pose_jump_p99_cm"] / joy["pose_jump_p99_cm"]
        out.append(("pose-jump p99 <= 1.2x the arrive joystick's",
                    f"{row['pose_jump_p99_cm']:.1f} vs {joy['pose_jump_p99_cm']:.1f} cm ({ratio:.2f}x)", ratio <= 1.2))
    return out


def picture(task, db, policy, cfg, path: Path, seed: int, episodes: int = 8) -> None:
    """Eight episodes, one panel each: the root's path, the target's circle and facing arrow
    (red), the character's heading where it stood (blue)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mmrl.rollout import FullPath, policy_actions

    run = FullPath(task, db, config=cfg, seed=seed, record=True, fast=True)
    fig, axes = plt.subplots(2, episodes // 2, figsize=(3.0 * episodes // 2, 6.2))
    for ax in axes.ravel():
        facing = float(run.env.env_state(0)["facing"])
        target = run.target.copy()
        while True:
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            if out["done"]:
                break
        roots = np.asarray(run.last_recording["roots"], np.float64)
        ax.plot(roots[:, 0], roots[:, 1], color="0.3", lw=1.2)
        ax.plot(*roots[0, :2], "o", color="0.3", ms=4)
        ax.add_patch(plt.Circle(target, cfg.success_radius, fill=False, color="tab:red", lw=1, ls="--"))
        for (x, z), yaw, color in ((target, facing, "tab:red"), (roots[-1, :2], roots[-1, 2], "tab:blue")):
            ax.arrow(x, z, 0.5 * math.sin(yaw), 0.5 * math.cos(yaw), width=0.012, head_width=0.1, color=color,
                     length_includes_head=True)
        ax.set_aspect("equal")
        ax.set_title(("rest" if out["success"] else "no rest") + f" in {out['episode_frames'] / db.fps:.1f} s",
                     fontsize=9)
        ax.tick_params(labelsize=7)
        pad = 0.8
        lo, hi = np.minimum(roots[:, :2].min(0), target) - pad, np.maximum(roots[:, :2].max(0), target) + pad
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
    fig.suptitle("arrive: the root's path (grey, from the dot), the target and its facing (red), "
                 "where the character stood facing (blue); x, z in meters", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="+", help="training run directories (the arrive task)")
    ap.add_argument("--data", nargs="*", default=None, help="BVH data (default: the first run's database)")
    ap.add_argument("--db", default=None, help="database .npz")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--standing-episodes", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="also run each RUN with these options changed (several separated by commas)")
    ap.add_argument("--picture", default=None, metavar="PNG", help="draw eight episodes of the first run")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from mmrl.commands.common import split_overrides
    from mmrl.motion.database import Database
    from mmrl.runs import RunDir
    from mmrl.tasks import get_task

    task = get_task("arrive")
    runs = [RunDir(r, require_run=True) for r in args.runs]
    if args.db:
        db = Database.load(args.db)
    elif args.data:
        db = Database.from_bvh(args.data)
    else:
        db = runs[0].database()
    controllers = []
    for run, name in zip(runs, args.runs):
        cfg = run.task_config(task)
        controllers.append((name, run.policy(), cfg))
        for item in args.set:
            (values,) = split_overrides(item.split(","), cfg)
            controllers.append((f"{name} ({item})", run.policy(), cfg.replace(**values)))
    results = {}
    for name, policy, cfg in controllers:
        results[name] = measure(task, db, policy, cfg, args)
        print(f"{name}: {json.dumps(results[name], default=float)}", flush=True)

    def f(v, spec=".1f"):
        return "" if v is None else format(v, spec)

    print("\n| run | success | position median / p95 (cm) | facing median / p95 (deg) | time to rest (s) | "
          "vs joystick (both finished) | sliding IK on / off | transitions/s | pose-jump p99 |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in results.items():
        print(f"| {name} | {100 * r['success_rate']:.1f}% | {f(r.get('final_position_error_cm_median'))} / "
              f"{f(r.get('final_position_error_cm_p95'))} | {f(r.get('final_facing_error_deg_median'))} / "
              f"{f(r.get('final_facing_error_deg_p95'))} | {f(r['time_s'], '.2f')} | {f(r.get('time_ratio'), '.2f')}x "
              f"({r['both_finished']}) | {f(r['foot_sliding_cm_per_s'])} / {f(r['foot_sliding_ik_off_cm_per_s'])} | "
              f"{f(r['transitions_per_s'], '.2f')} | {f(r['pose_jump_p99_cm'])} |")
        j = r["joystick"]
        print(f"| arrive joystick at {r['speed_m_per_s']:.2f} m/s | {100 * j['success_rate']:.1f}% | | | "
              f"{f(j['time_s'], '.2f')} | | {f(j['foot_sliding_cm_per_s'])} / {f(j['foot_sliding_ik_off_cm_per_s'])} | "
              f"{f(j['transitions_per_s'], '.2f')} | {f(j['pose_jump_p99_cm'])} |")
    print("\nwhile standing (3 s after each success):\n")
    print("| run | stood | sliding IK on / off | raw idle frames | transitions/s | pose-jump p99 | stop jump "
          "median / p95 | moved (median) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, r in results.items():
        for who, st in ((name, r.get("standing")), ("arrive joystick", r.get("joystick_standing"))):
            if st and st.get("stood"):
                print(f"| {who} | {st['stood']}/{st['episodes']} | {f(st['foot_sliding_cm_per_s'], '.2f')} / "
                      f"{f(st['foot_sliding_ik_off_cm_per_s'])} | {f(st['raw_idle']['foot_sliding_cm_per_s'])} | "
                      f"{f(st['transitions_per_s'], '.2f')} | {f(st['pose_jump_p99_cm'])} | "
                      f"{f(st['stop_pose_jump_median_cm'])} / {f(st['stop_pose_jump_p95_cm'])} | {f(st['moved_cm'])} cm |")
    for name, r in results.items():
        print(f"\n{name}:")
        for goal, measured, met in verdicts(r):
            print(f"  {'met    ' if met else 'NOT met'}  {goal}: {measured}")
    if args.picture:
        name, policy, cfg = controllers[0]
        picture(task, db, policy, cfg, Path(args.picture), args.seed)
        print(f"\nwrote {args.picture}")
    if args.json:
        Path(args.json).write_text(json.dumps({"episodes": args.episodes, "seed": args.seed, "results": results},
                                              indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
