"""A compressed controller against the database controller, on the same episodes (issue 27,
docs/compressed.md): the same policy drives both through the full path.

    python bench/bench_compressed.py --run RUN --compressed FILE [--episodes 100] [--seed 0]
        [--runtime-bench build/bench_compressed] [--json out.json]

Prints, for the database controller, the compressed one and the joystick on the database:
success, time to target, foot sliding with IK on and off, transitions/s, pose-jump p99, and
the raw-mocap floor; then the compressed controller's mean joint-position error against the
database controller's poses over the same decisions (at each of the database controller's
decisions the compressed one starts from the same frame's state, decides on the same query and
plays the same frames), and with --runtime-bench the C++ numbers
(file sizes, memory, load time, us per character per frame with the split).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

KEYS = ("success_rate", "mean_time_to_target_s", "foot_sliding_cm_per_s", "foot_sliding_ik_off_cm_per_s",
        "transitions_per_s", "pose_jump_p99_cm", "mean_speed_m_per_s")


def decision_errors(task, db, policy, config, cc, episodes: int, seed: int) -> dict:
    """The compressed controller's poses against the database controller's over the same
    decisions: the database controller plays ``episodes`` episodes; at each of its decisions the
    compressed controller starts from the state of the database's current frame, decides on the
    same query (projector, continuation rule, the same transition cost) and plays the same
    frames; the mean joint-position error (cm, character frame, every joint) of its frames
    against the database's, overall and where both continued / both jumped. ``runner_up``: at the
    database's jumps, the same error of the search's own second answer (the nearest frame of
    another clip) against its first: how far apart two near-equal answers of an exact search are."""
    import torch

    from mmrl.compress.pose import pose_targets
    from mmrl.compress.train import _positions
    from mmrl.rollout import FullPath, policy_actions

    run = FullPath(task, db, config=config, seed=seed, record=False)
    low, high = run.env.single_action_space.low, run.env.single_action_space.high
    y = pose_targets(db)
    F = run.config.frames_per_step
    states = cc.frame_states
    errors = {"all": [], "both_continue": [], "both_jump": [], "differ": [], "runner_up": []}
    feats = np.asarray(db.normalized_features, np.float32)
    valid = np.asarray(db.valid_mask, bool)
    ended = 0
    while ended < episodes:
        frame = int(run.env.env_state(0)["frame"])
        action = policy_actions(policy, run.obs[None]).reshape(-1)
        db_query = np.concatenate([feats[frame, :15], np.clip(action, low, high)])
        state = states[frame]
        query = np.concatenate([state[:15], np.clip(action, low, high)]).astype(np.float32)
        jump, chosen, _ = cc.core.decide(state, query, float(config.transition_cost))  # the env's rule (C++)
        rows = cc.core.playback(chosen, F)[0][1:]
        out = run.step(action)
        ended += int(out["done"])
        played = out["res"].frames[:out["step_frames"]]
        with torch.no_grad():
            p = _positions(torch.as_tensor(np.array(rows[:len(played)]), dtype=torch.float64), list(db.parents),
                           db.num_joints)
            q = _positions(torch.as_tensor(y[played], dtype=torch.float64), list(db.parents), db.num_joints)
        err = float(100.0 * (p - q).norm(dim=-1).mean())
        db_jump = bool(out["res"].transition)
        if db_jump:  # the search's runner-up outside the winner's clip, against the winner's frames
            j = int(out["res"].match)
            d = ((feats - db_query) ** 2).sum(1)
            d[~valid] = np.inf
            lo, hi = db.clip_ranges[db.frame_clip[j]]
            d[lo:hi] = np.inf
            j2 = int(np.argmin(d))
            with torch.no_grad():
                r = _positions(torch.as_tensor(y[j2 + 1:j2 + 1 + len(played)], dtype=torch.float64), list(db.parents),
                               db.num_joints)
            errors["runner_up"].append(float(100.0 * (r - q).norm(dim=-1).mean()))
        errors["all"].append(err)
        errors["both_jump" if (jump and db_jump) else "both_continue" if not (jump or db_jump) else "differ"].append(err)
    return {k: {"decisions": len(v), "joint_error_cm": float(np.mean(v)) if v else None} for k, v in errors.items()}


def episode_paths(task, db, policy, config, cc, episodes: int, seed: int):
    """The root paths (x, z) and targets of the first ``episodes`` full-path episodes."""
    from mmrl.rollout import FullPath, policy_actions

    run = FullPath(task, db, config=config, seed=seed, compressed=cc)
    paths = []
    while len(paths) < episodes:
        target = run.target.copy()
        out = run.step(policy_actions(policy, run.obs[None]).reshape(-1))
        if out["done"]:
            paths.append((np.asarray(run.last_recording["roots"])[:, :2], target, bool(out["success"])))
    return paths


def picture(path, task, db, policy, config, cc, out: dict, seed: int) -> None:
    """Left: the same episodes' root paths, database and compressed. Right: the quality numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.2))
    for comp, color, name in ((None, "tab:blue", "database"), (cc, "tab:orange", "compressed")):
        for k, (xz, target, ok) in enumerate(episode_paths(task, db, policy, config, comp, 6, seed)):
            ax.plot(xz[:, 0], xz[:, 1], color=color, lw=1.6, label=name if k == 0 else None)
            ax.plot(*xz[0], "o", color=color, ms=4)
            ax.plot(*target, "x", color="k", ms=7)
    ax.set_aspect("equal")
    ax.set_title("the same policy, the same 6 episodes (x: targets)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(loc="best")
    names = ("foot_sliding_cm_per_s", "foot_sliding_ik_off_cm_per_s", "transitions_per_s", "pose_jump_p99_cm")
    labels = ("sliding, IK on\n(cm/s)", "sliding, IK off\n(cm/s)", "transitions/s", "pose jump p99\n(cm)")
    x = np.arange(len(names))
    for k, (who, color) in enumerate((("database", "tab:blue"), ("compressed", "tab:orange"),
                                      ("joystick_database", "tab:gray"))):
        bx.bar(x + (k - 1) * 0.27, [out[who][n] or 0.0 for n in names], 0.27, color=color,
               label=who.replace("_", " on the "))
    bx.set_xticks(x, labels)
    bx.set_title(f"motion quality over {out['episodes']} episodes")
    bx.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", required=True, help="a plane training run")
    ap.add_argument("--compressed", required=True, help="its database's compressed file (mmrl compress)")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--runtime-bench", default=None, help="the bench_compressed binary (C++ numbers)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--picture", default=None, help="write the comparison's picture (PNG)")
    args = ap.parse_args(argv)

    import torch

    from mmrl.cli import main as cli
    from mmrl.compress.model import CompressedModel
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import evaluate_full_path
    from mmrl.runs import RunDir

    torch.set_num_threads(1)
    r = RunDir(args.run)
    task, db, policy, config = r.task, r.database(), r.policy(), r.task_config()
    cc = CompressedModel(args.compressed, db)
    out = {"run": args.run, "compressed": args.compressed, "episodes": args.episodes, "seed": args.seed}
    for name, pol, comp in (("database", policy, None), ("compressed", policy, cc),
                            ("joystick_database", JoystickPolicy.preset(db, "joystick"), None)):
        t0 = time.perf_counter()
        res = evaluate_full_path(task, db, pol, episodes=args.episodes, seed=args.seed, config=config, compressed=comp)
        out[name] = {k: res.get(k) for k in KEYS}
        out[name]["wall_s"] = time.perf_counter() - t0
        out.setdefault("raw_mocap", res.get("raw_mocap"))
    out["decisions"] = decision_errors(task, db, policy, config, cc, max(10, args.episodes // 5), args.seed)
    a, b = out["database"], out["compressed"]
    out["ratios"] = {
        "success_points": 100.0 * (b["success_rate"] - a["success_rate"]),
        "time_to_target": b["mean_time_to_target_s"] / a["mean_time_to_target_s"],
        "sliding_ik_off": b["foot_sliding_ik_off_cm_per_s"] / a["foot_sliding_ik_off_cm_per_s"],
        "transitions_per_s": b["transitions_per_s"] / a["transitions_per_s"],
        "pose_jump_p99": b["pose_jump_p99_cm"] / a["pose_jump_p99_cm"],
    }
    fmt = lambda v: "n/a" if v is None else f"{v:.3f}"  # noqa: E731
    print(f"{args.episodes} plane episodes, seed {args.seed}, the same policy ({args.run}):")
    print(f"  {'':<20}" + "".join(f"{k[:22]:>24}" for k in KEYS))
    for name in ("database", "compressed", "joystick_database"):
        print(f"  {name:<20}" + "".join(f"{fmt(out[name][k]):>24}" for k in KEYS))
    print(f"  raw mocap floor: {out['raw_mocap']}")
    print(f"  compressed vs database: {json.dumps({k: round(v, 3) for k, v in out['ratios'].items()})}")
    d = out["decisions"]
    print("  joint error against the database controller's poses over the same decisions (cm): " +
          ", ".join(f"{k} {v['joint_error_cm'] if v['joint_error_cm'] is None else round(v['joint_error_cm'], 2)} "
                    f"({v['decisions']} decisions)" for k, v in d.items()))
    if args.runtime_bench:
        with tempfile.TemporaryDirectory() as tmp:
            a_path, b_path = Path(tmp) / "db.mmrl", Path(tmp) / "c.mmrl"
            assert cli(["export", args.run, "-o", str(a_path)]) == 0
            assert cli(["export", args.run, "--compressed", args.compressed, "-o", str(b_path)]) == 0
            text = subprocess.run([args.runtime_bench, str(a_path), str(b_path)], check=True, capture_output=True,
                                  text=True).stdout
        print(text)
        out["runtime"] = text
    if args.picture:
        picture(args.picture, task, db, policy, config, cc, out, args.seed)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
