"""The paper's Figure 7: the moving-obstacles task with and without the hit reward and the curriculum.

    python bench/bench_figure7.py [--data DIR | --db FILE.npz] [--steps 2400000] [--seeds 0 1 2]
        [--variants ours no-hit-reward no-curriculum [no-hit-no-curriculum]] [--no-train] [--out DIR]
        [--episodes 100] [--fast-episodes 1000] [--eval-seed 1000] [--preset mmrl] [--set KEY=VALUE ...]

1. For each seed, trains three runs with the same env-step budget through the ``mmrl train
   obstacles`` command line: ours, ``--no-hit-reward`` and ``--no-curriculum`` (in
   OUT/seed<K>/<name>; ``--preset`` and ``--set`` options go to every run). ``--variants`` can add
   ``no-hit-no-curriculum`` (both flags), which the paper does not show. A run that already
   holds the full budget is reused and a shorter one is resumed, so an interrupted bench
   continues where it stopped and more seeds can be added later. ``--no-train`` only evaluates
   and plots the runs already there (a variant may then have fewer seeds than another).
2. Plots success ratio, episode length and curriculum stage against env steps from each run's
   metrics.csv into OUT/figure7.png: one thin line per seed, the mean over seeds in bold.
3. Prints, per run: final curriculum stage, the env step at which stage 10 was reached and
   passed (its window of 200 episodes above 40%: every stage passed), deterministic success and
   collision rates at the last stage on the fast path (``mmrl.rollout.evaluate_fast``,
   --fast-episodes episodes, with the standard error) and on the full-path character
   (``mmrl.rollout.evaluate_full_path``, --episodes episodes; 0 skips it), the same
   episodes (--eval-seed) for every run; and the joystick baseline (which ignores obstacles) on
   those episodes.
4. With several seeds, a summary per variant: seeds that passed every stage, the median step
   at which they did, the fast-path success as mean ± std over seeds, and the difference to
   the first variant (ours) paired by seed. Evaluations are cached in each run directory
   (figure7_eval.json); everything also goes to OUT/figure7.json.

A run of the full budget (2.4M steps) takes about 12 minutes on 2 cores; check the script end
to end with a tiny one (``--steps 20000``).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"
#: (name, extra ``mmrl train obstacles`` flags), in the paper's legend order; then a run without both, which
#: the paper does not show (only with --variants): it completes the two-by-two table of the ablations.
VARIANTS = (("ours", []), ("no-hit-reward", ["--no-hit-reward"]), ("no-curriculum", ["--no-curriculum"]),
            ("no-hit-no-curriculum", ["--no-hit-reward", "--no-curriculum"]))
PAPER_VARIANTS = [n for n, _ in VARIANTS[:3]]
LAST_STAGE = 10


def run_status(run: Path, steps: int) -> str:
    """'done' (a checkpoint holding the budget), 'partial' (a shorter checkpoint) or 'new'."""
    from mmrl.viz.plots import read_metrics

    if not (run / "latest.pt").exists():
        return "new"
    try:
        last = read_metrics(run)["step"][-1]
    except (FileNotFoundError, ValueError):
        return "partial"
    return "done" if last >= steps else "partial"


def train_variants(variants, db_path: Path, out: Path, steps: int, seed: int, preset, sets, threads: int) -> None:
    """Train (or reuse, or resume) VARIANTS of one seed in OUT/seed<K>/<name>."""
    from mmrl.cli import main as mmrl_main

    for name, flags in variants:
        run = out / f"seed{seed}" / name
        status = run_status(run, steps)
        if status == "done":
            print(f"reusing {run} (holds {steps:,} steps)", flush=True)
            continue
        if status == "partial":
            argv = ["train", "obstacles", "--resume", str(run), "--steps", str(steps), "--threads", str(threads),
                    "--no-progress"]
        else:
            argv = ["train", "obstacles", "--db", str(db_path), "--steps", str(steps), "--seed", str(seed),
                    "--out", str(run), "--threads", str(threads), "--no-progress", *flags]
            if preset:
                argv += ["--preset", preset]
            for s in sets:
                argv += ["--set", s]
        print("mmrl " + " ".join(argv), flush=True)
        code = mmrl_main(argv)
        if code != 0:
            raise SystemExit(f"mmrl train failed for {run} (exit code {code})")


def resample(m: dict, key: str, grid: np.ndarray) -> np.ndarray:
    """A metrics column on a common step grid (linear between logged rows, NaN past the run's end)."""
    ok = np.isfinite(m.get(key, np.array([np.nan])))
    if not ok.any():
        return np.full(grid.shape, np.nan)
    x, y = m["step"][ok], m[key][ok]
    out = np.interp(grid, x, y)
    out[grid > x[-1]] = np.nan
    return out


def plot(out: Path, curves: dict, steps: int) -> Path:
    """curves: {variant: {seed: metrics}}; thin lines per seed, bold mean over the seeds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = np.linspace(0, steps, 241)
    keys = ("success_rate", "episode_length", "curriculum_stage")
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    for i, (name, runs) in enumerate(curves.items()):
        color = f"C{i}"
        for ax, key in zip(axes, keys):
            ys = np.array([resample(m, key, grid) for m in runs.values()])
            if len(runs) > 1:
                for y in ys:
                    ax.plot(grid, y, color=color, lw=0.6, alpha=0.35)
            with np.errstate(invalid="ignore"):
                mean = np.nanmean(ys, axis=0) if np.isfinite(ys).any() else ys[0]
            label = name if len(runs) == 1 else f"{name} (mean of {len(runs)} seeds)"
            ax.plot(grid, mean, color=color, lw=1.8, label=label)
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
    from mmrl.runs import RunDir

    return RunDir(run).task_config()


def evaluate_run(policy, db, cfg, args, cache: Path = None, checkpoint: Path = None) -> dict:
    """Stage-10 success and collisions on the fast path and the full-path character.

    Cached in CACHE, keyed by the evaluation options and CHECKPOINT's size and modification time.
    """
    from mmrl import get_task
    from mmrl.io import atomic_write_text
    from mmrl.rollout import evaluate_fast, evaluate_full_path

    task = get_task("obstacles")

    key = {"eval_seed": args.eval_seed, "fast_episodes": args.fast_episodes, "episodes": args.episodes}
    if checkpoint is not None:
        st = checkpoint.stat()
        key["checkpoint"] = [st.st_size, st.st_mtime_ns]
    if cache is not None and cache.exists():
        saved = json.loads(cache.read_text())
        if saved.get("key") == key:
            return saved["result"]
    fast = evaluate_fast(task, db, policy, episodes=args.fast_episodes, seed=args.eval_seed, config=cfg,
                                   stage=LAST_STAGE)
    result = {"success": fast["success_rate"], "stderr": fast["success_stderr"], "collision": fast["collision_rate"],
              "success_full": float("nan"), "collision_full": float("nan")}
    if args.episodes > 0:
        full = evaluate_full_path(task, db, policy, episodes=args.episodes, seed=args.eval_seed, config=cfg,
                                  stage=LAST_STAGE)
        result.update(success_full=full["success_rate"], collision_full=full["collision_rate"])
    if cache is not None:
        atomic_write_text(cache, json.dumps({"key": key, "result": result}))
    return result


def curriculum_steps(m: dict) -> tuple:
    """(final stage, step at which the last stage was reached or None, step at which it was passed or None)."""
    stage = m.get("curriculum_stage", np.array([np.nan]))
    final = float(stage[np.isfinite(stage)][-1]) if np.isfinite(stage).any() else float("nan")
    reached = int(m["step"][stage >= LAST_STAGE][0]) if (stage >= LAST_STAGE).any() else None
    if reached is not None and stage[0] >= LAST_STAGE:
        reached = 0  # started there (no curriculum)
    done = m.get("curriculum_complete", np.zeros(1)) > 0
    passed = int(m["step"][done][0]) if done.any() else None
    return final, reached, passed


def summarize(rows: list, seeds: list, names: list) -> list:
    """Per variant over its seeds: stages passed, median step, success mean/std, and the difference to the
    first variant paired by seed (over the seeds both have)."""
    by = {(r["run"], r["seed"]): r for r in rows}
    summary = []
    for name in names:
        have = [s for s in seeds if (name, s) in by]
        if not have:
            continue
        ok = np.array([by[name, s]["success"] for s in have])
        passed = [by[name, s]["passed_at"] for s in have if by[name, s]["passed_at"] is not None]
        entry = {"run": name, "seeds": len(have), "passed_all": len(passed),
                 "median_passed_at": float(np.median(passed)) if passed else None,
                 "success_mean": float(ok.mean()), "success_std": float(ok.std(ddof=1)) if len(ok) > 1 else 0.0,
                 "success_min": float(ok.min()), "success_max": float(ok.max())}
        common = [s for s in have if (names[0], s) in by]
        if name != names[0] and common:
            diff = np.array([by[names[0], s]["success"] - by[name, s]["success"] for s in common])
            entry.update(paired_seeds=len(common), diff_to_first_mean=float(diff.mean()),
                         diff_to_first_stderr=float(diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1 else 0.0,
                         first_better=int((diff > 0).sum()))
        summary.append(entry)
    return summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--data", default=None, help=f"BVH directory (default {DEFAULT_DATA})")
    src.add_argument("--db", default=None, help="a database saved by 'mmrl db build'")
    ap.add_argument("--steps", type=int, default=2_400_000, help="env steps per run (default 2.4M, the paper's)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="training seeds (default: --seed)")
    ap.add_argument("--seed", type=int, default=0, help="the training seed of a single-seed bench (default 0)")
    ap.add_argument("--variants", nargs="+", default=PAPER_VARIANTS, choices=[n for n, _ in VARIANTS],
                    help="which runs (default the paper's three; the first is the reference of the paired "
                         "differences)")
    ap.add_argument("--episodes", type=int, default=100, help="full-path evaluation episodes (0 skips them)")
    ap.add_argument("--fast-episodes", type=int, default=1000, help="fast-path evaluation episodes at the last stage")
    ap.add_argument("--eval-seed", type=int, default=1000, help="seed of the evaluation episodes (all runs share them)")
    ap.add_argument("--no-train", action="store_true",
                    help="only evaluate and plot the runs already in OUT (missing ones are left out)")
    ap.add_argument("--threads", type=int, default=0, help="C++ env threads (0 = all cores)")
    ap.add_argument("--out", default=None, help="output directory (default: a temporary one)")
    ap.add_argument("--preset", choices=("paper", "mmrl", "mmrl-cnn"), default=None,
                    help="'mmrl train obstacles --preset' for every run (default: the command's default, 'mmrl'; "
                    "the nine-seed tables of docs/obstacles.md were measured with what is now 'mmrl-cnn')")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="passed to every new 'mmrl train obstacles' run (repeatable)")
    args = ap.parse_args()
    seeds = list(dict.fromkeys(args.seeds or [args.seed]))
    names = list(dict.fromkeys(args.variants))
    if args.steps < 1 or args.episodes < 0 or args.fast_episodes < 2:
        raise SystemExit("--steps must be positive, --episodes non-negative and --fast-episodes at least 2")

    import mmrl
    from mmrl.rl import ppo
    from mmrl.viz.plots import read_metrics
    from mmrl.rl.policies import JoystickPolicy

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="mmrl-figure7-"))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.db:
        db_path = Path(args.db)
        db = mmrl.Database.load(db_path)
    else:  # build once, share the saved database between the runs
        db = mmrl.Database.from_bvh(args.data or DEFAULT_DATA)
        db_path = out / "db.npz"
        db.save(db_path)
    print(f"{db!r}; ready in {time.perf_counter() - t0:.1f} s; output in {out}", flush=True)

    variants = [v for v in VARIANTS if v[0] in names]
    if not args.no_train:
        for seed in seeds:
            train_variants(variants, db_path, out, args.steps, seed, args.preset, args.set, args.threads)
    curves = {}
    for name in names:
        for seed in seeds:
            run = out / f"seed{seed}" / name
            if (run / "latest.pt").exists():
                curves.setdefault(name, {})[seed] = read_metrics(run)
            else:
                print(f"no run in {run}; left out", flush=True)
    if not curves:
        raise SystemExit(f"no runs in {out}")
    names = [n for n in names if n in curves]
    print(f"wrote {plot(out, curves, args.steps)}")

    rows = []
    for seed in seeds:
        for name in names:
            if seed not in curves[name]:
                continue
            run, m = out / f"seed{seed}" / name, curves[name][seed]
            final, reached, passed = curriculum_steps(m)
            ev = evaluate_run(ppo.load_policy(run / "latest.pt"), db, task_config(run), args,
                              cache=run / "figure7_eval.json", checkpoint=run / "latest.pt")
            rows.append({"run": name, "seed": seed, "final_stage": final, "reached_at": reached, "passed_at": passed,
                         **ev, "env_steps": int(m["step"][-1]), "wall_s": float(m["wall_s"][-1])})
    first = rows[0]
    joy = evaluate_run(JoystickPolicy.preset(db, "joystick"), db,
                       task_config(out / f"seed{first['seed']}" / first["run"]), args)
    rows.append({"run": "joystick", "seed": None, "final_stage": float("nan"), "reached_at": None,
                 "passed_at": None, **joy, "env_steps": 0, "wall_s": 0.0})

    print(f"\nstage-{LAST_STAGE} evaluation, deterministic, eval seed {args.eval_seed}: fast path "
          f"({args.fast_episodes} episodes) and full-path character ({args.episodes} episodes)")
    print(f"{'run':<21}{'seed':>5}{'final stage':>12}{'stage 10 at':>12}{'passed at':>11}{'success (fast)':>18}"
          f"{'collision':>11}{'success (full)':>16}{'collision':>11}{'env steps':>12}{'wall s':>9}")
    step_text = lambda s: "-" if s is None else "start" if s == 0 else f"{s / 1e6:.2f}M"  # noqa: E731
    for r in rows:
        st = "-" if not np.isfinite(r["final_stage"]) else f"{r['final_stage']:.0f}"
        seed = "-" if r["seed"] is None else str(r["seed"])
        print(f"{r['run']:<21}{seed:>5}{st:>12}{step_text(r['reached_at']):>12}{step_text(r['passed_at']):>11}"
              f"{r['success']:>11.3f} ±{r['stderr']:.3f}{r['collision']:>11.3f}{r['success_full']:>16.3f}"
              f"{r['collision_full']:>11.3f}{r['env_steps']:>12,}{r['wall_s']:>9.1f}")

    summary = summarize(rows, seeds, names) if len(seeds) > 1 else []
    if summary:
        print(f"\nover {len(seeds)} seeds ({', '.join(map(str, seeds))}): fast-path stage-{LAST_STAGE} success; "
              f"joystick {joy['success']:.3f}")
        print(f"{'run':<21}{'all stages passed':>19}{'median step':>13}{'success mean ± std':>21}{'min':>7}{'max':>7}"
              f"{names[0] + ' minus run':>22}{names[0] + ' better':>16}")
        for e in summary:
            med = "-" if e["median_passed_at"] is None else f"{e['median_passed_at'] / 1e6:.2f}M"
            diff = (f"{e['diff_to_first_mean']:+.3f} ±{e['diff_to_first_stderr']:.3f}" if "diff_to_first_mean" in e
                    else "-")
            better = f"{e['first_better']}/{e['paired_seeds']}" if "first_better" in e else "-"
            print(f"{e['run']:<21}{e['passed_all']:>13}/{e['seeds']:<5}{med:>13}"
                  f"{e['success_mean']:>13.3f} ±{e['success_std']:.3f}{e['success_min']:>7.3f}{e['success_max']:>7.3f}"
                  f"{diff:>22}{better:>16}")
    report = {"steps": args.steps, "seeds": seeds, "eval_seed": args.eval_seed, "fast_episodes": args.fast_episodes,
              "episodes": args.episodes, "preset": args.preset, "set": args.set, "rows": rows, "summary": summary}
    (out / "figure7.json").write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {out / 'figure7.json'}")


if __name__ == "__main__":
    main()
