"""Throughput of the moving-obstacles env (sensors, hits, per-frame collisions, matching).

Runs ``ObstaclesVectorEnv`` on a database (default: all of ../shared/data/bandai-namco-2)
for batches of envs and two kinds of actions:

- policy-like: a random valid frame's normalized trajectory features + 0.5 std noise (the
  features are normalized per block, so 0.5 in normalized units is about 0.5 std);
- uniform: uniform in the action box.

Prints steps/s (env steps, i.e. characters x RL steps, per second of wall time), the same
actions on PlaneVecEnv (no obstacles: the matching cost alone), and the
episode outcome rates. No asserts: this is a measurement.

    python bench/bench_obstacles_env.py [--data DIR | --db FILE.npz] [--envs 64 128 256] [--seconds 5]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import mmrl
from mmrl.tasks.curriculum import stage_params
from mmrl.tasks.obstacles import ObstaclesVectorEnv
from mmrl.tasks.plane import PlaneVectorEnv

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def action_stream(kind: str, db, space, n: int, rng: np.random.Generator, pool: int = 64):
    """A fixed pool of action batches (so generating actions does not count in the timing)."""
    if kind == "uniform":
        batches = rng.uniform(space.low, space.high, (pool, n, 12))
    else:
        valid = np.flatnonzero(db.valid_mask)
        traj = db.normalized_features[:, 15:27]
        frames = rng.choice(valid, (pool, n))
        batches = traj[frames] + 0.5 * rng.standard_normal((pool, n, 12))
    return np.ascontiguousarray(batches, np.float32)


def run(env, actions, seconds: float):
    env.reset(seed=0)
    for k in range(5):  # warm-up
        env.step(actions[k % len(actions)])
    steps = ended = success = collision = truncated = 0
    cpu_start = time.process_time()
    start = time.perf_counter()
    k = 0
    while time.perf_counter() - start < seconds:
        _, _, term, trunc, infos = env.step(actions[k % len(actions)])
        k += 1
        steps += env.num_envs
        done = term | trunc
        if done.any():
            ended += int(done.sum())
            success += int(infos["success"][done].sum())
            if "collision" in infos:
                collision += int(infos["collision"][done].sum())
            truncated += int(trunc.sum())
    elapsed = time.perf_counter() - start
    cpu = time.process_time() - cpu_start
    return steps / elapsed, steps / cpu, ended, success, collision, truncated


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="BVH directory (default: bandai-namco-2)")
    ap.add_argument("--db", type=Path, default=None, help="a saved database .npz instead of --data")
    ap.add_argument("--envs", type=int, nargs="+", default=[64, 128, 256])
    ap.add_argument("--seconds", type=float, default=5.0, help="timed seconds per configuration")
    ap.add_argument("--threads", type=int, default=0, help="C++ threads (0 = all cores)")
    ap.add_argument("--stage", type=int, default=10, help="curriculum stage 1..10 of the scenes")
    args = ap.parse_args()

    t0 = time.perf_counter()
    db = mmrl.Database.load(args.db) if args.db else mmrl.Database.from_bvh(args.data)
    _ = db.matcher
    print(f"database: {db.num_frames} frames ({db.minutes:.1f} min) loaded in {time.perf_counter() - t0:.1f} s")
    speed, half = stage_params(args.stage)
    print(f"stage {args.stage}: obstacle speed <= {speed:.2f} m/s, targets in +-{half:.2f} m; threads {args.threads or 'all'}")
    rng = np.random.default_rng(0)
    print("steps/s: env steps per wall second; per CPU-s: per second of process CPU time (on a busy machine,\n"
          "x cores is the figure for idle cores). plane: the same actions on mmrl/Plane-v0 (matching only).")
    print(f"{'envs':>5} {'actions':>8} {'steps/s':>9} {'per CPU-s':>10} {'plane steps/s':>14} {'plane per CPU-s':>16} "
          f"{'episodes':>9} {'success':>8} {'collision':>10} {'truncated':>10}")
    for n in args.envs:
        env = ObstaclesVectorEnv(n, db=db, num_threads=args.threads)
        env.set_stage(speed, half)
        plane = PlaneVectorEnv(n, db=db, num_threads=args.threads)
        for kind in ("policy", "uniform"):
            actions = action_stream(kind, db, env.single_action_space, n, rng)
            sps, cps, ended, succ, coll, trunc = run(env, actions, args.seconds)
            plane_sps, plane_cps, *_ = run(plane, actions, args.seconds / 2)
            print(f"{n:>5} {kind:>8} {sps:>9,.0f} {cps:>10,.0f} {plane_sps:>14,.0f} {plane_cps:>16,.0f} {ended:>9} "
                  f"{succ / max(ended, 1):>8.1%} {coll / max(ended, 1):>10.1%} {trunc / max(ended, 1):>10.1%}")
        env.close()
        plane.close()


if __name__ == "__main__":
    main()
