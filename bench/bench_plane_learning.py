"""Learning speed on the plane task (issue 5's goals), on all of the shared data.

    python bench/bench_plane_learning.py [--data DIR] [--seed 0] [--out DIR]

1. Trains with the default PPOConfig for 20 s of training wall time (database loading
   excluded) and evaluates the deterministic policy on 1000 fixed episodes.
2. Resumes the same run to 1,000,000 env steps, reports the wall time, and evaluates again.
3. Evaluates the joystick baselines (walking and running speed) on the same episodes.
"""
from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import mmrl
from mmrl.rl import ppo
from mmrl.rollout import evaluate_fast
from mmrl.tasks.plane import PlaneVectorEnv


def evaluate_plane(policy, db, **kwargs):
    return evaluate_fast(mmrl.get_task("plane"), db, policy, **kwargs)

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--out", default=None, help="run directory (default: a temporary one)")
    args = ap.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="mmrl-learning-"))
    if (out / "latest.pt").exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    db = mmrl.Database.from_bvh(args.data)
    _ = db.matcher
    print(f"{db!r}; loaded in {time.perf_counter() - t0:.1f} s (excluded from training time)")

    env = PlaneVectorEnv(64, db=db)
    cfg = ppo.PPOConfig(seed=args.seed, max_seconds=args.seconds, total_steps=10**12, progress=False,
                        snapshot_steps=(20_000, 100_000, 533_000, 1_000_000))
    r1 = ppo.train(env, cfg, out)
    e1 = evaluate_plane(ppo.load_policy(r1.checkpoint), db, episodes=args.episodes)
    print(f"after {r1.wall_s:.1f} s ({r1.global_step:,} steps): success {e1['success_rate']:.3f}, "
          f"time to target {e1['mean_time_to_target_s']:.2f} s")

    cfg.max_seconds, cfg.total_steps = None, args.steps
    r2 = ppo.train(env, cfg, out, resume=True)
    e2 = evaluate_plane(ppo.load_policy(r2.checkpoint), db, episodes=args.episodes)
    print(f"after {r2.global_step:,} steps in {r2.wall_s:.1f} s: success {e2['success_rate']:.3f}, "
          f"time to target {e2['mean_time_to_target_s']:.2f} s")

    try:
        from mmrl.rl.policies import JoystickPolicy
    except ImportError:
        print("joystick baseline not available in this build")
        return
    for name in ("joystick", "joystick-run"):
        ej = evaluate_plane(JoystickPolicy.preset(db, name), db, episodes=args.episodes)
        print(f"{name:<13}: success {ej['success_rate']:.3f}, time to target {ej['mean_time_to_target_s']:.2f} s")
    print(f"run directory: {out}")


if __name__ == "__main__":
    main()
