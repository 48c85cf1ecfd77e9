"""Fast-path evaluation of target-reaching policies: success rate and time to target.

Every episode runs in its own environment of one batched env, so N episodes take about as
long as the longest one. Quality metrics (foot sliding, pose jumps) need the full path:
see ``mmrl eval``.
"""
from __future__ import annotations


import numpy as np


def evaluate_plane(policy, db, *, episodes: int = 1000, seed: int = 12345, config=None,
                   deterministic: bool = True, num_threads: int = 0) -> dict:
    """Run ``episodes`` plane-task episodes (one per environment) and summarize them.

    Args:
        policy: anything with ``act(obs[N, 17], deterministic=...) -> actions[N, 12]``.
        db: the Database the policy was trained on.
        seed: the episodes' seed (starts, headings and targets); the same seed gives the
            same episodes for every policy, so policies can be compared.

    Returns:
        ``success_rate``, ``mean_time_to_target_s`` (successful episodes), ``mean_steps``,
        ``episodes``.
    """
    from .envs import PlaneVectorEnv

    env = PlaneVectorEnv(episodes, db=db, config=config, num_threads=num_threads)
    obs, _ = env.reset(seed=seed)
    done = np.zeros(episodes, bool)
    success = np.zeros(episodes, bool)
    length = np.zeros(episodes, np.int64)
    seconds_per_step = env.config.frames_per_step / db.fps
    while not done.all():
        try:
            actions = policy.act(obs, deterministic=deterministic)
        except TypeError:
            actions = policy.act(obs)
        obs, _, term, trunc, info = env.step(actions)
        ended = (term | trunc) & ~done
        if ended.any():
            success[ended] = info["success"][ended]
            length[ended] = info["episode_length"][ended]
            done |= ended
    env.close()
    ok = success.sum()
    return {
        "episodes": int(episodes),
        "success_rate": float(success.mean()),
        "mean_time_to_target_s": float(length[success].mean() * seconds_per_step) if ok else float("nan"),
        "mean_steps": float(length.mean()),
    }
