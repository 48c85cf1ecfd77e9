"""RLlib against mmrl's own PPO on the plane task, same env and machine, one run.

    python bench/bench_rllib.py --db db.npz            # all shared data: mmrl db build ../shared/data/bandai-namco-2 -o db.npz
    python bench/bench_rllib.py --quick                # synthetic data, tiny budgets (a smoke test)
    python bench/bench_rllib.py --obstacles RUN        # also report an obstacles --backend rllib run's curriculum

Prints, for our PPO, RLlib with 1 worker and RLlib with 2 workers (each `mmrl train plane
... --seconds S`, the default preset): steps/s and the training time until the success of
the last 200 training episodes first reaches 90%. Then a scaling curve: RLlib steps/s with
1, 2 and 4 workers (4 oversubscribes the 2 cores), and each worker's memory against the
database's size (USS: the worker's private memory; the database's arrays are mapped from
Ray's object store, so they count as shared). Writes everything to --json as well.
"""
from __future__ import annotations

import argparse
import csv
import functools
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def time_to_success(run: Path, level: float = 0.9, window: int = 200):
    """(wall s, step) when the success ratio of the last ``window`` finished training episodes
    first reaches ``level`` (each CSV row's episodes weighted by their count), or None."""
    recent: list = []
    with open(run / "metrics.csv", newline="") as f:
        for row in csv.DictReader(f):
            n = int(float(row["episodes"] or 0))
            if n and row["success_rate"] not in ("", "nan"):
                k = int(round(float(row["success_rate"]) * n))
                recent.extend([1] * k + [0] * (n - k))
                recent = recent[-window:]
                if len(recent) >= window and np.mean(recent) >= level:
                    return float(row["wall_s"]), int(float(row["step"]))
    return None


def last_row(run: Path) -> dict:
    with open(run / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return rows[-1]


def train(out: Path, data: list, seconds: float, backend: str, workers: int = 0) -> dict:
    cmd = [sys.executable, "-m", "mmrl", "train", "plane", *data, "--seconds", str(seconds), "--out", str(out),
           "--no-progress", "--seed", "0"]
    if backend == "rllib":
        cmd += ["--backend", "rllib", "--workers", str(workers)]
    t0 = time.time()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    row = last_row(out)
    hit = time_to_success(out)
    return {"backend": backend, "workers": workers, "seconds": float(row["wall_s"]), "steps": int(float(row["step"])),
            "steps_per_s": int(float(row["step"])) / max(float(row["wall_s"]), 1e-9),
            "time_to_90_s": hit[0] if hit else None, "steps_to_90": hit[1] if hit else None,
            "process_s": time.time() - t0}


def scaling(db_path, workers_list, seconds: float) -> list:
    """RLlib steps/s per worker count, in-process, plus each worker's memory."""
    import ray

    import mmrl
    from mmrl.integrations.rllib import RLlibConfig, RLlibRun, process_memory
    from mmrl.integrations.rllib.envs import worker_report

    db = mmrl.Database.load(db_path) if db_path else mmrl.default_database()
    task = mmrl.get_task("plane")
    preset = task.presets[task.default_preset]
    task_cfg = task.default_config().replace(**{k: v for k, v in preset.items() if hasattr(task.default_config(), k)})
    out = []
    for workers in workers_list:
        ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False, configure_logging=False)
        cfg = RLlibConfig(workers=workers, gamma=preset.get("gamma", 0.99), total_steps=10**12, progress=False,
                          tensorboard=False)
        run = RLlibRun(task, db, task_cfg, cfg, Path(tempfile.mkdtemp()))
        try:
            run.algo.train()  # warm-up
            steps, t0 = 0, time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                steps += int(run.algo.train()["env_runners"]["num_env_steps_sampled"])
            rate = steps / (time.perf_counter() - t0)
            reports = run.algo.env_runner_group.foreach_env_runner(
                functools.partial(worker_report, run.db_handle), local_env_runner=False)
            out.append({"workers": workers, "steps_per_s": rate, "db_mb": run.db_handle.nbytes / 2**20,
                        "worker_memory": [w["memory"] for w in reports],
                        "borrowed": [w["borrowed"] for w in reports], "driver_memory": process_memory()})
        finally:
            run.stop()
            ray.shutdown()
    return out


def copy_baseline(db_path) -> dict:
    """A process that loads its own copy of the database (what each worker would hold without
    the object store): its private memory before and after."""
    code = ("import json, sys, mmrl; from mmrl.integrations.rllib import process_memory; "
            "before = process_memory(); db = mmrl.Database.load(sys.argv[1]) if sys.argv[1] else mmrl.default_database(); "
            "db.matcher; print(json.dumps({'before': before, 'after': process_memory()}))")
    out = subprocess.run([sys.executable, "-c", code, db_path or ""], check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--db", default=None, help="database file (default: synthetic data)")
    ap.add_argument("--seconds", type=float, default=240.0, help="training budget of each plane run")
    ap.add_argument("--scaling-seconds", type=float, default=40.0)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--quick", action="store_true", help="synthetic data, 20 s runs, 10 s scaling")
    ap.add_argument("--obstacles", default=None, help="an obstacles --backend rllib run directory to summarize")
    ap.add_argument("--json", default="bench_rllib.json")
    args = ap.parse_args()
    if args.quick:
        args.db, args.seconds, args.scaling_seconds, args.workers = None, 20.0, 10.0, [1, 2]
    data = ["--db", args.db] if args.db else []
    results: dict = {"cores": os.cpu_count(), "db": args.db or "synthetic"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        results["plane"] = [train(tmp / "ppo", data, args.seconds, "ppo"),
                            train(tmp / "rllib1", data, args.seconds, "rllib", 1),
                            train(tmp / "rllib2", data, args.seconds, "rllib", 2)]
    results["scaling"] = scaling(args.db, args.workers, args.scaling_seconds)
    results["copy_baseline"] = copy_baseline(args.db)
    if args.obstacles:
        run = Path(args.obstacles)
        with open(run / "metrics.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        passed = [r for r in rows if r.get("curriculum_complete") == "1"]
        results["obstacles"] = {"steps": int(float(rows[-1]["step"])), "wall_s": float(rows[-1]["wall_s"]),
                                "final_stage": int(rows[-1]["curriculum_stage"]),
                                "all_stages_passed_at": int(float(passed[0]["step"])) if passed else None}
    Path(args.json).write_text(json.dumps(results, indent=2))
    report(results)
    return 0


def report(r: dict) -> None:
    ours = r["plane"][0]
    print(f"plane task, {r['db']}, {r['cores']} cores; each run --seconds budget, default preset")
    print(f"{'trainer':<18}{'steps/s':>10}{'x ours':>8}{'time to 90%':>13}{'steps to 90%':>14}")
    for row in r["plane"]:
        name = "mmrl PPO" if row["backend"] == "ppo" else f"RLlib, {row['workers']} worker" + "s" * (row["workers"] > 1)
        t = f"{row['time_to_90_s']:.1f} s" if row["time_to_90_s"] is not None else "not reached"
        s = f"{row['steps_to_90']:,}" if row["steps_to_90"] is not None else "-"
        print(f"{name:<18}{row['steps_per_s']:>10.0f}{row['steps_per_s'] / ours['steps_per_s']:>8.2f}{t:>13}{s:>14}")
    print("RLlib scaling (steps/s; more workers than cores is oversubscribed):")
    base = r["scaling"][0]["steps_per_s"]
    for row in r["scaling"]:
        mem = row["worker_memory"]
        uss = np.mean([m["uss_mb"] for m in mem])
        shared = np.mean([m["shared_mb"] for m in mem])
        print(f"  {row['workers']} workers: {row['steps_per_s']:8.0f} steps/s ({row['steps_per_s'] / base:.2f}x of 1); "
              f"worker USS {uss:.0f} MB, shared {shared:.0f} MB, RSS {np.mean([m['rss_mb'] for m in mem]):.0f} MB; "
              f"database {row['db_mb']:.0f} MB")
    cb = r["copy_baseline"]
    print(f"a process holding its own copy: USS {cb['before']['uss_mb']:.0f} -> {cb['after']['uss_mb']:.0f} MB "
          f"(+{cb['after']['uss_mb'] - cb['before']['uss_mb']:.0f} MB for the database and its index)")
    if "obstacles" in r:
        o = r["obstacles"]
        print(f"obstacles --backend rllib: {o['steps']:,} steps in {o['wall_s']:.0f} s, stage {o['final_stage']}; "
              f"all stages passed at {o['all_stages_passed_at'] if o['all_stages_passed_at'] else 'not reached'}")


if __name__ == "__main__":
    sys.exit(main())
