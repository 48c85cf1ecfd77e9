"""Motion quality against speed: time to target and foot sliding of trained policies and the
joysticks on the same episodes (issue 14, docs/quality.md).

    python bench/bench_quality.py --db db.npz --out runs/quality --seeds 0 1 2
    python bench/bench_quality.py --db db.npz --out runs/quality --no-train   # evaluate and plot existing runs
    python bench/bench_quality.py --dbs synthetic other-skeleton one.npz all.npz --out runs/quality-dbs

``--dbs`` (issue 25): on each database (a ``.npz``, a BVH file or folder, ``synthetic``: the
package's own data, or ``other-skeleton``: synthetic clips on a second skeleton with other joint
names and channel orders), train the default ``mmrl train plane --seconds S`` (``--train-args``
adds options), evaluate it and the equal-speed joystick line (``mmrl.eval.reference``, ``--line``
speeds) on the same episodes, and write one table, OUT/quality-dbs.json and one figure
(``--figure``, default docs/quality_dbs.png) with a panel per database.

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
        "transitions_per_s", "pose_jump_p99_cm", "matched_cost_mean", "mean_speed_m_per_s")


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


def database_for(spec: str, out: Path):
    """(name, Database, .npz path) of a --dbs entry; the .npz is written under OUT/dbs when built here."""
    import mmrl

    path = Path(spec)
    if spec == "synthetic":
        db, name = mmrl.default_database(), "synthetic"
    elif spec == "other-skeleton":
        import sys
        import tempfile

        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from test_import_axes_fps import other_skeleton_database  # the tests' second skeleton (needs scipy)

        clips = ((0.6, 0.0), (1.3, 0.3), (1.2, -0.5), (1.5, 0.0), (2.6, -0.2), (3.2, 0.2))
        db, name = other_skeleton_database(Path(tempfile.mkdtemp()), clips=clips, seconds=12.0), "other-skeleton"
    elif path.suffix == ".npz":
        return path.stem, mmrl.Database.load(path), path
    else:
        db, name = mmrl.Database.from_bvh(path), path.name
    npz = out / "dbs" / f"{name}.npz"
    db.save(npz)
    return name, db, npz


def run_databases(args) -> None:
    import mmrl
    from mmrl.cli import main as cli
    from mmrl.io import atomic_write_text
    from mmrl.eval.reference import against_line, joystick_line, joystick_speeds
    from mmrl.rollout import evaluate_full_path
    from mmrl.runs import RunDir

    out = Path(args.out)
    task = mmrl.get_task("plane")
    table = {}
    for spec in args.dbs:
        name, db, npz = database_for(spec, out)
        line = None
        for seed in args.seeds:  # one row per seed; the joysticks' line once per database
            run = out / f"{name}-seed{seed}"
            if not (run / "latest.pt").exists() and not args.no_train:
                budget = ["--steps", str(args.train_steps)] if args.train_steps else ["--seconds", str(args.seconds)]
                code = cli(["train", "plane", "--db", str(npz), *budget, "--seed",
                            str(seed), "--out", str(run), "--no-progress", *args.train_args])
                if code != 0:
                    raise SystemExit(f"training {run} failed ({code})")
            rd = RunDir(run)
            cfg = rd.task_config()
            res = evaluate_full_path(task, db, rd.policy(), episodes=args.episodes, seed=args.eval_seed, config=cfg)
            if line is None:
                line = joystick_line(task, db, speeds=joystick_speeds(db, args.line), episodes=args.episodes,
                                     seed=args.eval_seed, config=cfg)
            row = {k: res.get(k) for k in KEYS}
            row.update(against_line(res, line))
            row.update(frames=db.num_frames, raw_mocap=res.get("raw_mocap"), transition_cost=cfg.transition_cost,
                       seed=seed)
            key = name if len(args.seeds) == 1 else f"{name} seed {seed}"
            table[key] = row
            print(f"{key}: {json.dumps({k: v for k, v in row.items() if k != 'joystick_line'})}", flush=True)
    print("| database | frames | success | time to target (s) | transitions/s | sliding IK off | line at that "
          "time | IK off / line | mean speed (m/s) | IK off / line at that speed | sliding IK on | raw mocap |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    f2 = lambda v: "n/a" if v is None else f"{v:.2f}"  # noqa: E731
    for name, r in table.items():
        print(f"| {name} | {r['frames']:,} | {100 * r['success_rate']:.0f}% | {f2(r['mean_time_to_target_s'])} | "
              f"{f2(r['transitions_per_s'])} | {f2(r['foot_sliding_ik_off_cm_per_s'])} | "
              f"{f2(r['joystick_line_sliding_ik_off_cm_per_s'])} | {f2(r['sliding_ik_off_vs_joystick_line'])} | "
              f"{f2(r.get('mean_speed_m_per_s'))} | {f2(r.get('sliding_ik_off_vs_joystick_line_at_speed'))} | "
              f"{f2(r['foot_sliding_cm_per_s'])} | {f2((r['raw_mocap'] or {}).get('foot_sliding_cm_per_s'))} |")
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "quality-dbs.json", json.dumps(table, indent=1))
    plot_databases(table, Path(args.figure or "docs/quality_dbs.png"))
    print(f"wrote {out / 'quality-dbs.json'} and {args.figure or 'docs/quality_dbs.png'}")


def plot_databases(table: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mmrl.io import atomic_path

    n = len(table)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.6), constrained_layout=True, squeeze=False)
    for ax, (name, r) in zip(axes[0], table.items()):
        pts = sorted((j["mean_time_to_target_s"], j["foot_sliding_ik_off_cm_per_s"], j["speed_m_per_s"])
                     for j in r["joystick_line"] if j["mean_time_to_target_s"] is not None)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "s-", color="gray", label="joysticks (speeds in m/s)")
        for t, v, sp in pts:
            ax.annotate(f"{sp:.1f}", (t, v), textcoords="offset points", xytext=(3, 3), fontsize=7, color="gray")
        if r["mean_time_to_target_s"] is not None:
            ax.plot([r["mean_time_to_target_s"]], [r["foot_sliding_ik_off_cm_per_s"]], "o", color="C0", ms=8,
                    label="default policy")
        floor = (r.get("raw_mocap") or {}).get("foot_sliding_cm_per_s")
        if floor is not None:
            ax.axhline(floor, ls="--", color="gray", lw=1)
        ax.set_title(f"{name} ({r['frames']:,} frames)", fontsize=9)
        ax.set_xlabel("time to target (s)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("foot sliding, IK off (cm/s)")
    axes[0][0].legend(fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", help="a database saved by 'mmrl db build' (all shared data for the goals)")
    p.add_argument("--dbs", nargs="+", help="run the default on each of these databases (see above)")
    p.add_argument("--seconds", type=float, default=30.0, help="with --dbs: the training budget of each")
    p.add_argument("--train-steps", type=int, default=None,
                   help="with --dbs: train this many steps instead of --seconds (the same result on a busy machine)")
    p.add_argument("--line", type=int, default=5, help="with --dbs: joystick speeds on the line")
    p.add_argument("--train-args", nargs=argparse.REMAINDER, default=[],
                   help="with --dbs: more 'mmrl train plane' arguments (last on the command line)")
    p.add_argument("--out", default="runs/quality")
    p.add_argument("--steps", type=int, default=1_000_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--eval-seed", type=int, default=1)
    p.add_argument("--no-train", action="store_true", help="only evaluate the runs already in OUT")
    p.add_argument("--figure", default=None, help="default docs/quality.png (docs/quality_dbs.png with --dbs)")
    args = p.parse_args()
    if args.dbs:
        run_databases(args)
        return
    if not args.db:
        p.error("--db or --dbs is required")
    args.figure = args.figure or "docs/quality.png"

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
