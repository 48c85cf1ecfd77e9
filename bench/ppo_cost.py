"""Cost of PPO's own work per env step, on the numpy toy target env.

Prints, per configuration, microseconds per env step (summed over envs) for
the env, for acting (normalize, policy forward, sampling, plus the batched
value pass and GAE after each rollout) and for the update, as logged in the
``env_us``/``act_us``/``update_us`` columns of metrics.csv.

    python bench/ppo_cost.py [--steps 200000]
"""
from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _toyenv import PointMassTargetVecEnv  # noqa: E402

from mmrl.rl.networks import ObstacleActorCritic  # noqa: E402
from mmrl.rl.ppo import PPOConfig, train  # noqa: E402


def measure(label: str, env, cfg: PPOConfig, policy_factory=None) -> None:
    with tempfile.TemporaryDirectory() as out:
        result = train(env, cfg, out, policy_factory=policy_factory)
        with open(result.metrics_csv, newline="") as file:
            rows = list(csv.DictReader(file))[1:]  # skip the warm-up iteration
    median = {k: float(np.median([float(r[k]) for r in rows])) for k in ("env_us", "act_us", "update_us", "sps")}
    print(f"{label:<44} env {median['env_us']:7.2f} us  act {median['act_us']:6.2f} us  "
          f"update {median['update_us']:6.2f} us  per step; {median['sps']:9.0f} steps/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200_000)
    args = parser.parse_args()
    base = dict(progress=False, tensorboard=False, checkpoint_interval_steps=10**9)
    for num_envs in (16, 64, 256):
        for threads in (1, 2):
            cfg = PPOConfig(total_steps=args.steps, torch_threads=threads, **base)
            env = PointMassTargetVecEnv(num_envs, extra_obs_dims=13, extra_act_dims=10)
            measure(f"plane MLP 17->12, {num_envs} envs, {threads} thread(s)", env, cfg)
    layout = (("goal", 2), ("pose", 2), ("pose_rest", 13), ("maps", 512))
    for threads in (1, 2):
        cfg = PPOConfig(total_steps=max(args.steps // 10, 16_384), torch_threads=threads,
                        obs_norm_exclude=ObstacleActorCritic.map_range(layout), **base)
        env = PointMassTargetVecEnv(64, extra_obs_dims=13 + 512, extra_act_dims=10)
        measure(f"obstacle CNN 529->12, 64 envs, {threads} thread(s)", env, cfg,
                lambda obs_dim, act_dim: ObstacleActorCritic(act_dim, layout=layout))


if __name__ == "__main__":
    main()
