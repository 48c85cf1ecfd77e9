"""Motion quality against speed: time to target and foot sliding of trained policies and the
joysticks on the same episodes (issue 14, docs/quality.md).

    python bench/bench_quality.py --db db.npz --out runs/quality --seeds 0 1 2
    python bench/bench_quality.py --db db.npz --out runs/quality --no-train   # evaluate and plot existing runs

Each variant is trained with ``mmrl train plane`` (its options below) into OUT/<variant>-seed<k>
(an existing run is reused), then every policy and both joysticks are evaluated on the full path
with the same episodes (``mmrl.rollout.evaluate_full_path``, IK on; the IK-off sliding comes
from the same run). Prints a markdown table with the raw-mocap floor and writes
OUT/quality.json and the figure (default docs/quality.png): time to target against foot
sliding with IK off, one point per policy, the joysticks as references.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

#: Variants: name -> extra ``mmrl train`` arguments (``mmrl train plane`` alone is "quality").
VARIANTS = {
    "paper": ["--preset", "paper"],
    "bias-20": ["--preset", "paper", "--set", "transition_cost=20"],
    "bias-60": ["--preset", "paper", "--set", "transition_cost=60"],
    "bias-100": ["--preset", "paper", "--set", "transition_cost=100"],
    "quality": ["--preset", "quality"],
    "pose-2": ["--preset", "quality", "--set", "transition_pose_weight=2"],
    "smooth": ["--preset", "smooth"],
}
KEYS = ("success_rate", "mean_time_to_target_s", "foot_sliding_cm_per_s", "foot_sliding_ik_off_cm_per_s",
        "transitions_per_s", "pose_jump_p99_cm", "matched_cost_mean")


def train(run: Path, db: str, steps: int, seed: int, extra) -> None:
    from mmrl.cli import main

    if (run / "latest.pt").exists():
        return
    code = main(["train", "plane", "--db", db, "--steps", str(steps), "--seed", str(seed), "--out", str(run),
                 "--no-progress", *extra])
    if code != 0:
        raise SystemExit(f"training {run} failed ({code})")


def evaluate(policy, db, task, config, episodes: int, seed: int) -> dict:
    from mmrl.rollout import evaluate_full_path

    res = evaluate_full_path(task, db, policy, episodes=episodes, seed=seed, config=config)
    out = {k: res.get(k) for k in KEYS}
    out["raw_mocap"] = res.get("raw_mocap")
    return out


def plot(rows: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mmrl.io import atomic_path

    fig, ax = plt.subplots(figsize=(7, 5), constrained_layout=True)
    for k, (name, results) in enumerate(rows.items()):
        xs = [r["foot_sliding_ik_off_cm_per_s"] for r in results]
        ys = [r["mean_time_to_target_s"] for r in results]
        marker = "s" if name.startswith("joystick") else "o"
        ax.scatter(xs, ys, s=60, marker=marker, color=f"C{k}", label=name, edgecolor="black", linewidth=0.5)
    floor = next(r["raw_mocap"] for results in rows.values() for r in results if r.get("raw_mocap"))
    if floor:
        ax.axvline(floor["foot_sliding_cm_per_s"], ls="--", color="gray", lw=1)
        ax.text(floor["foot_sliding_cm_per_s"], ax.get_ylim()[1], " raw mocap", va="top", color="gray")
    ax.set_xlabel("foot sliding with IK off (cm/s, lower is better)")
    ax.set_ylabel("time to target (s, lower is better)")
    ax.set_title("plane task: speed against motion quality, same 100 episodes")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", required=True, help="a database saved by 'mmrl db build' (all shared data for the goals)")
    p.add_argument("--out", default="runs/quality")
    p.add_argument("--steps", type=int, default=1_000_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--eval-seed", type=int, default=1)
    p.add_argument("--no-train", action="store_true", help="only evaluate the runs already in OUT")
    p.add_argument("--figure", default="docs/quality.png")
    args = p.parse_args()

    import mmrl
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.runs import RunDir

    out = Path(args.out)
    db = mmrl.Database.load(args.db)
    task = mmrl.get_task("plane")
    rows = {}
    for name in ("joystick", "joystick-run"):
        rows[name] = [evaluate(JoystickPolicy.preset(db, name), db, task, None, args.episodes, args.eval_seed)]
    for variant in args.variants:
        for seed in args.seeds:
            run = out / f"{variant}-seed{seed}"
            if not args.no_train:
                train(run, args.db, args.steps, seed, VARIANTS[variant])
            if not (run / "latest.pt").exists():
                continue
            rd = RunDir(run)
            rows.setdefault(variant, []).append(
                evaluate(rd.policy(), db, task, rd.task_config(), args.episodes, args.eval_seed))
    floor = rows["joystick"][0]["raw_mocap"]
    print(f"raw mocap (clips played straight): foot sliding {floor['foot_sliding_cm_per_s']:.1f} cm/s "
          f"(p95 {floor['foot_sliding_p95_cm_per_s']:.1f})")
    print("| controller | runs | success | time to target (s) | sliding IK on | sliding IK off | transitions/s | "
          "pose jump p99 | matched cost |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name, results in rows.items():
        cells = [" / ".join(f"{r[k]:.2f}" if k != "success_rate" else f"{100 * r[k]:.0f}%" for r in results)
                 for k in KEYS]
        print(f"| {name} | {len(results)} | " + " | ".join(cells) + " |")
    out.mkdir(parents=True, exist_ok=True)
    from mmrl.io import atomic_write_text

    atomic_write_text(out / "quality.json", json.dumps(rows, indent=1))
    plot(rows, Path(args.figure))
    print(f"wrote {out / 'quality.json'} and {args.figure}")


if __name__ == "__main__":
    main()
