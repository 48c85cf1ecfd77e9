"""Learner throughput of obstacle training: env steps per second of `mmrl train obstacles` with
each network, in the same run (the machine is noisy: compare the ratios).

    python bench/bench_obstacles_learner.py [--db FILE.npz] [--seconds 90] [--networks cnn small-cnn mlp]
        [--set KEY=VALUE ...] [--rounds 1]

Each network trains from scratch for ``--seconds`` with ``--preset mmrl-small``'s options (the
path filter, 8 minibatch steps per rollout; plus ``--set``) into
a temporary directory; the bench reads its metrics.csv and prints steps/s and the split of a
step's wall time (env, policy forward, update: µs per env step), then each network's ratio to
the first. Rounds alternate the order.
"""
from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path


def train_once(db: str, network: str, seconds: float, sets, out: Path) -> dict:
    from mmrl.cli import main

    args = ["train", "obstacles", "--seconds", str(seconds), "--out", str(out), "--no-progress",
            "--preset", "mmrl-small", "--set", f"network={network}"]
    for kv in sets:
        args += ["--set", kv]
    if db:
        args += ["--db", db]
    if main(args) != 0:
        raise SystemExit(f"training with network={network} failed")
    rows = list(csv.DictReader(open(out / "metrics.csv")))
    last = rows[-1]
    split = {k: sum(float(r[k]) for r in rows) / len(rows) for k in ("env_us", "act_us", "update_us")}
    return {"steps": int(last["step"]), "wall_s": float(last["wall_s"]),
            "steps_per_s": int(last["step"]) / float(last["wall_s"]), **split,
            "stage": int(last["curriculum_stage"])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--db", default=None, help="database .npz (default: the synthetic data)")
    ap.add_argument("--seconds", type=float, default=90.0)
    ap.add_argument("--networks", nargs="+", default=["cnn", "small-cnn", "mlp"])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args(argv)
    results = {n: [] for n in args.networks}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            order = args.networks if r % 2 == 0 else list(reversed(args.networks))
            for n in order:
                res = train_once(args.db, n, args.seconds, args.set, Path(tmp) / f"{n}-{r}")
                results[n].append(res)
                print(f"round {r} {n}: {res}", flush=True)
    base = args.networks[0]
    base_sps = sum(x["steps_per_s"] for x in results[base]) / len(results[base])
    print("\n| network | steps/s | vs " + base + " | env / policy / update (µs per env step) | stage reached |")
    print("|---|---:|---:|---|---:|")
    for n, rs in results.items():
        sps = sum(x["steps_per_s"] for x in rs) / len(rs)
        split = " / ".join(f"{sum(x[k] for x in rs) / len(rs):.0f}" for k in ("env_us", "act_us", "update_us"))
        print(f"| {n} | {sps:,.0f} | {sps / base_sps:.2f}x | {split} | {max(x['stage'] for x in rs)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
