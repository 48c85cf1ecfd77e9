"""A task env's step (the plane task's by default, --task obstacles), where its fixed cost shows:
64 envs, near actions (and policy-like ones), for two builds of mmrl measured in the same run,
alternating, and their ratio.

    python bench/bench_env_step.py                          # this build alone
    python bench/bench_env_step.py --compare OLD_PKG NEW_PKG --rounds 3

OLD_PKG / NEW_PKG are directories holding an ``mmrl`` package with its built ``_core`` (for
example ``cp -r python/mmrl DIR/mmrl`` plus the ``_core*.so`` of that build); each round runs
both, one after the other, in fresh processes. The database is all shared data (cached as an
npz under /tmp), else ``--db PATH``. Action sets are bench_plane_env.py's: near = the current
frame's own trajectory features + 0.05 std noise (the match keeps the continuation: the step's
fixed cost dominates), policy-like = a random frame's trajectory features + 0.5 std noise.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"
CACHE = Path("/tmp/mmrl-bench-env-step-db.npz")


def load_db(args):
    import mmrl

    if args.db:
        return mmrl.Database.load(args.db)
    if CACHE.exists():
        return mmrl.Database.load(CACHE)
    db = mmrl.Database.from_bvh(args.data)
    db.save(CACHE)
    return db


def measure(args) -> dict:
    import mmrl

    db = load_db(args)
    env = mmrl.get_task(args.task).make_vector_env(args.envs, db=db, num_threads=args.threads)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    rows = np.flatnonzero(db.valid_mask)
    t = np.ascontiguousarray(db.normalized_features[:, 15:])
    sd = t[rows].std(0)
    n = args.envs
    policy = [(t[rng.choice(rows, n)] + rng.normal(0, 0.5, (n, 12)) * sd).astype(np.float32) for _ in range(8)]
    noise = [(rng.normal(0, 0.05, (n, 12)) * sd).astype(np.float32) for _ in range(8)]
    frames = np.empty(n, np.int64)
    sets = {"near": lambda k: t[_frames(env, frames)] + noise[k % 8], "policy-like": lambda k: policy[k % 8]}
    out = {"mmrl": os.path.dirname(mmrl.__file__)}
    for name, actions in sets.items():
        env.step(actions(0))
        k, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < args.seconds:
            env.step(actions(k))
            k += 1
        out[name] = k * n / (time.perf_counter() - t0)
    return out


def _frames(env, out):
    env._core.current_frames(out)
    return out


def compare(args) -> None:
    rows = {"old": [], "new": []}
    for r in range(args.rounds):
        for label, pkg in (("old", args.compare[0]), ("new", args.compare[1])):
            cmd = [sys.executable, __file__, "--envs", str(args.envs), "--seconds", str(args.seconds),
                   "--threads", str(args.threads), "--task", args.task, "--json"] + (["--db", args.db] if args.db else [])
            env = dict(os.environ, PYTHONPATH=str(Path(pkg).resolve()))
            res = json.loads(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout)
            rows[label].append(res)
            print(f"round {r + 1} {label:3s} near {res['near']:>10,.0f}  policy-like {res['policy-like']:>9,.0f} "
                  f"steps/s  ({res['mmrl']})", flush=True)
    for name in ("near", "policy-like"):
        old = np.median([x[name] for x in rows["old"]])
        new = np.median([x[name] for x in rows["new"]])
        print(f"{name:12s} median old {old:>10,.0f}  new {new:>10,.0f} steps/s   new / old = {new / old:.2f}x")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--db", default=None, help="a database .npz instead of --data")
    ap.add_argument("--task", default="plane", help="the task whose env steps (plane, obstacles)")
    ap.add_argument("--envs", type=int, default=64)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--compare", nargs=2, metavar=("OLD_PKG", "NEW_PKG"))
    ap.add_argument("--json", action="store_true", help="print one JSON line (what --compare reads)")
    args = ap.parse_args()
    if args.compare:
        compare(args)
        return
    res = measure(args)
    print(json.dumps(res) if args.json else res)


if __name__ == "__main__":
    main()
