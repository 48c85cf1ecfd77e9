"""The paper's Figure 7: the moving-obstacles task with and without the hit reward and the curriculum.

    python bench/bench_figure7.py [--data DIR | --db FILE.npz] [--steps 2400000] [--seed 0]
        [--out DIR] [--episodes 100] [--fast-episodes 1000] [--preset mmrl] [--set KEY=VALUE ...]

1. Trains three runs with the same env-step budget through the ``mmrl train obstacles``
   command line: ours, ``--no-hit-reward`` and ``--no-curriculum`` (each in OUT/<name>,
   ``--preset`` and ``--set`` options passed to every run).
2. Plots success ratio, episode length and curriculum stage against env steps from each run's
   metrics.csv into OUT/figure7.png.
3. Prints a table: final curriculum stage, the env step at which stage 10 was reached and
   passed (its window of 200 episodes above 40%: every stage passed), deterministic success and collision rates at the
   last stage on the fast path (``mmrl.evaluation.evaluate_obstacles_fast``, --fast-episodes
   episodes, with the success rate's standard error) and on the full-path character
   (``mmrl.obstacle_rollouts.evaluate_obstacles``, --episodes episodes), the same episodes
   for every run; env steps and training wall time; the joystick baseline (which ignores
   obstacles) on the same episodes.

The full budget (2.4M steps per run) takes about 12 minutes a run on 2 cores; check the script end to end with
a tiny one (``--steps 20000``).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"
#: (name, extra ``mmrl train obstacles`` flags), in the paper's legend order.
VARIANTS = (("ours", []), ("no-hit-reward", ["--no-hit-reward"]), ("no-curriculum", ["--no-curriculum"]))
LAST_STAGE = 10


def train_variants(db_path: Path, out: Path, steps: int, seed: int, preset, sets, threads: int) -> dict:
    from mmrl.cli import main as mmrl_main

    wall = {}
    for name, flags in VARIANTS:
        run = out / name
        argv = ["train", "obstacles", "--db", str(db_path), "--steps", str(steps), "--seed", str(seed),
                "--out", str(run), "--threads", str(threads), "--no-progress", *flags]
        if preset:
            argv += ["--preset", preset]
        for s in sets:
            argv += ["--set", s]
        print("mmrl " + " ".join(argv), flush=True)
        t0 = time.perf_counter()
        code = mmrl_main(argv)
        wall[name] = time.perf_counter() - t0
        if code != 0:
            raise SystemExit(f"mmrl train failed for {name} (exit code {code})")
    return wall


def plot(out: Path, curves: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    for name, m in curves.items():
        steps = m["step"]
        for ax, key in zip(axes, ("success_rate", "episode_length", "curriculum_stage")):
            if key in m:
                ok = np.isfinite(m[key])
                ax.plot(steps[ok], m[key][ok], label=name, lw=1.5)
    for ax, title in zip(axes, ("success ratio", "episode length (steps)", "curriculum stage")):
        ax.set_title(title)
        ax.set_xlabel("env steps")
        ax.grid(alpha=0.3)
    axes[0].set_ylim(-0.02, 1.02)
    axes[2].set_ylim(0.5, LAST_STAGE + 0.5)
    axes[0].legend()
    path = out / "figure7.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def task_config(run: Path):
    from dataclasses import fields

    from mmrl.obstacles import ObstaclesConfig

    saved = json.loads((run / "config.json").read_text()).get("task_config", {})
    names = {f.name for f in fields(ObstaclesConfig)}
    return ObstaclesConfig(**{k: v for k, v in saved.items() if k in names})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--data", default=None, help=f"BVH directory (default {DEFAULT_DATA})")
    src.add_argument("--db", default=None, help="a database saved by 'mmrl db build'")
    ap.add_argument("--steps", type=int, default=2_400_000, help="env steps per run (default 2.4M, the paper's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=100, help="full-path evaluation episodes at the last stage")
    ap.add_argument("--fast-episodes", type=int, default=1000, help="fast-path evaluation episodes at the last stage")
    ap.add_argument("--threads", type=int, default=0, help="C++ env threads (0 = all cores)")
    ap.add_argument("--out", default=None, help="output directory (default: a temporary one)")
    ap.add_argument("--preset", choices=("paper", "mmrl"), default=None,
                    help="'mmrl train obstacles --preset' for every run (default: the command's, 'paper')")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="passed to every 'mmrl train obstacles' run (repeatable)")
    args = ap.parse_args()
    if args.steps < 1 or args.episodes < 1 or args.fast_episodes < 1:
        raise SystemExit("--steps, --episodes and --fast-episodes must be positive")

    import mmrl
    from mmrl import ppo
    from mmrl.evaluation import evaluate_obstacles_fast
    from mmrl.obstacle_rollouts import evaluate_obstacles
    from mmrl.plots import read_metrics
    from mmrl.policies import JoystickPolicy

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="mmrl-figure7-"))
    out.mkdir(parents=True, exist_ok=True)
    for name, _ in VARIANTS:
        if (out / name / "latest.pt").exists():
            raise SystemExit(f"{out / name} already holds a run; choose another --out")
    t0 = time.perf_counter()
    if args.db:
        db_path = Path(args.db)
        db = mmrl.Database.load(db_path)
    else:  # build once, share the saved database between the runs
        db = mmrl.Database.from_bvh(args.data or DEFAULT_DATA)
        db_path = out / "db.npz"
        db.save(db_path)
    print(f"{db!r}; ready in {time.perf_counter() - t0:.1f} s; output in {out}", flush=True)

    wall = train_variants(db_path, out, args.steps, args.seed, args.preset, args.set, args.threads)
    curves = {name: read_metrics(out / name) for name, _ in VARIANTS}
    print(f"wrote {plot(out, curves)}")

    def evaluate(policy, run: Path) -> tuple:
        cfg = task_config(run)
        fast = evaluate_obstacles_fast(policy, db, episodes=args.fast_episodes, seed=args.seed + 1000, config=cfg,
                                       stage=LAST_STAGE)
        full = evaluate_obstacles(db, policy, episodes=args.episodes, seed=args.seed + 1000, config=cfg,
                                  stage=LAST_STAGE)
        return (fast["success_rate"], fast["success_stderr"], fast["collision_rate"], full["success_rate"],
                full["collision_rate"])

    rows = []
    for name, _ in VARIANTS:
        run, m = out / name, curves[name]
        stage = m.get("curriculum_stage", np.array([np.nan]))
        final = stage[np.isfinite(stage)][-1] if np.isfinite(stage).any() else float("nan")
        reached = m["step"][stage >= LAST_STAGE][0] if (stage >= LAST_STAGE).any() else None
        done = m.get("curriculum_complete", np.zeros(1)) > 0
        passed = m["step"][done][0] if done.any() else None
        rows.append((name, final, reached, passed, *evaluate(ppo.load_policy(run / "latest.pt"), run),
                     int(m["step"][-1]), wall[name]))
    joy = evaluate(JoystickPolicy.preset(db, "joystick"), out / VARIANTS[0][0])
    rows.append(("joystick", float("nan"), None, None, *joy, 0, 0.0))

    print(f"\nstage-{LAST_STAGE} evaluation, deterministic: fast path ({args.fast_episodes} episodes) and "
          f"full-path character ({args.episodes} episodes)")
    print(f"{'run':<15}{'final stage':>12}{'stage 10 at':>12}{'passed at':>11}{'success (fast)':>18}{'collision':>11}"
          f"{'success (full)':>16}{'collision':>11}{'env steps':>12}{'wall s':>9}")
    step_text = lambda s: "-" if s is None else f"{s / 1e6:.2f}M"  # noqa: E731
    for name, stage, reached, passed, ok, err, coll, ok_full, coll_full, steps, seconds in rows:
        st = "-" if not np.isfinite(stage) else f"{stage:.0f}"
        print(f"{name:<15}{st:>12}{step_text(reached):>12}{step_text(passed):>11}{ok:>11.3f} ±{err:.3f}{coll:>11.3f}"
              f"{ok_full:>16.3f}{coll_full:>11.3f}{steps:>12,}{seconds:>9.1f}")

if __name__ == "__main__":
    main()
