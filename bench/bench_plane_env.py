"""Plane-task env throughput on the fast path, against the batched match alone and against
a gymnasium SyncVectorEnv of the single-env wrapper, in the same run.

    python bench/bench_plane_env.py [--data DIR] [--envs 64 256 4096] [--seconds 3]

Action sets: policy-like (a random database frame's trajectory features + 0.5 std noise),
near (the current frame's own trajectory features + 0.05 std noise, as a trained policy that
asks for plausible motion gives) and uniform random over the action box.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import mmrl
from mmrl.tasks.plane import PlaneEnv, PlaneVectorEnv

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def action_sets(db, env, n, rng, count=8):
    """Each set is a function step_index -> actions (N, 12)."""
    rows = np.flatnonzero(db.valid_mask)
    t = db.normalized_features[:, 15:]
    sd = t[rows].std(0)
    policy = [(t[rng.choice(rows, n)] + rng.normal(0, 0.5, (n, 12)) * sd).astype(np.float32) for _ in range(count)]
    noise = [(rng.normal(0, 0.05, (n, 12)) * sd).astype(np.float32) for _ in range(count)]
    low, high = env.single_action_space.low, env.single_action_space.high
    uniform = [rng.uniform(low, high, (n, 12)).astype(np.float32) for _ in range(count)]
    return {
        "policy-like": lambda i: policy[i % count],
        "near": lambda i: t[env.current_frames()] + noise[i % count],
        "uniform": lambda i: uniform[i % count],
    }


def time_loop(fn, seconds):
    fn(0)
    t0 = time.perf_counter()
    k = 0
    while time.perf_counter() - t0 < seconds:
        fn(k)
        k += 1
    return k, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--envs", type=int, nargs="+", default=[64, 256, 4096])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--threads", type=int, default=0)
    args = ap.parse_args()
    t0 = time.perf_counter()
    db = mmrl.Database.from_bvh(args.data)
    print(f"{db!r} loaded in {time.perf_counter() - t0:.1f} s; {os.cpu_count()} cores")
    t0 = time.perf_counter()
    _ = db.matcher
    print(f"matcher built in {time.perf_counter() - t0:.2f} s")
    rng = np.random.default_rng(0)
    print(f"{'envs':>6} {'actions':<12} {'env steps/s':>12} {'match q/s':>12} {'step/match':>10}")
    for n in args.envs:
        env = PlaneVectorEnv(n, db=db, num_threads=args.threads)
        env.reset(seed=0)
        for name, acts in action_sets(db, env, n, rng).items():
            k, dt = time_loop(lambda i: env.step(acts(i)), args.seconds)
            sps = k * n / dt
            # The batched match alone on the same kind of queries: the pose part of the env's
            # current frames and the (clipped) actions.
            frames = env.current_frames()
            qs = [np.concatenate([db.normalized_features[frames, :15],
                                  np.clip(acts(i), env.single_action_space.low, env.single_action_space.high)], 1)
                  .astype(np.float32) for i in range(8)]
            bounds = np.where(db.valid_mask[frames], frames, -1).astype(np.int64)
            windows = db.controller_windows(frames)  # the env's match skips these rows too
            km, dtm = time_loop(lambda i: db.matcher.match(qs[i % len(qs)], bounds, windows), args.seconds)
            mps = km * n / dtm
            print(f"{n:>6} {name:<12} {sps:>12,.0f} {mps:>12,.0f} {mps / sps:>10.2f}")
    # Peer: gymnasium's SyncVectorEnv of the single-env wrapper, 64 envs.
    import gymnasium as gym

    n = 64
    sync = gym.vector.SyncVectorEnv([lambda: PlaneEnv(db=db) for _ in range(n)])
    sync.reset(seed=0)
    ours = PlaneVectorEnv(n, db=db, num_threads=args.threads)
    ours.reset(seed=0)
    acts = action_sets(db, ours, n, rng)["policy-like"]
    k, dt = time_loop(lambda i: sync.step(acts(i)), args.seconds)
    sync_sps = k * n / dt
    k, dt = time_loop(lambda i: ours.step(acts(i)), args.seconds)
    ours_sps = k * n / dt
    print(f"SyncVectorEnv(64 x PlaneEnv): {sync_sps:,.0f} steps/s; PlaneVectorEnv(64): {ours_sps:,.0f} steps/s "
          f"= {ours_sps / sync_sps:.1f}x")


if __name__ == "__main__":
    main()
