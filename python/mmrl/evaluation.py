"""Fast-path evaluation of target-reaching policies: success rate and time to target.

Every episode runs in its own environment of one batched env, so N episodes take about as
long as the longest one. Quality metrics (foot sliding, pose jumps) need the full path:
see ``mmrl eval``.
"""
from __future__ import annotations


import numpy as np


def first_episodes(env, policy, seed: int, deterministic: bool = True) -> dict:
    """Run ``env`` (a vector env) until each environment's first episode has ended; returns
    arrays of each one's ``success``, ``collision`` (False where the env has none) and
    ``length``. ``policy.act(obs[N, D], deterministic=...) -> actions[N, 12]``. Closes ``env``."""
    episodes = env.num_envs
    obs, _ = env.reset(seed=seed)
    done = np.zeros(episodes, bool)
    out = {k: np.zeros(episodes, bool) for k in ("success", "collision")}
    length = np.zeros(episodes, np.int64)
    while not done.all():
        try:
            actions = policy.act(obs, deterministic=deterministic)
        except TypeError:
            actions = policy.act(obs)
        obs, _, term, trunc, info = env.step(actions)
        ended = (term | trunc) & ~done
        if ended.any():
            for k in out:
                if k in info:
                    out[k][ended] = info[k][ended]
            length[ended] = info["episode_length"][ended]
            done |= ended
    env.close()
    out["length"] = length
    return out


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
    r = first_episodes(env, policy, seed, deterministic)
    success, length = r["success"], r["length"]
    seconds_per_step = env.config.frames_per_step / db.fps
    ok = success.sum()
    return {
        "episodes": int(episodes),
        "success_rate": float(success.mean()),
        "mean_time_to_target_s": float(length[success].mean() * seconds_per_step) if ok else float("nan"),
        "mean_steps": float(length.mean()),
    }


def evaluate_obstacles_fast(policy, db, *, episodes: int = 1000, seed: int = 12345, config=None, stage: int = 10,
                            deterministic: bool = True, num_threads: int = 0) -> dict:
    """Moving-obstacles episodes at curriculum ``stage`` (one per environment, fast path).

    The same seed gives the same episodes (starts, targets, obstacles) for every policy.
    Returns ``success_rate``, ``collision_rate``, ``truncation_rate``, ``mean_steps``,
    ``episodes``, ``stage`` and ``success_stderr`` (the binomial standard error).
    """
    from .obstacle_rollouts import stage_params
    from .obstacles import ObstaclesVectorEnv

    env = ObstaclesVectorEnv(episodes, db=db, config=config, num_threads=num_threads)
    env.set_stage(*stage_params(stage), stage)
    r = first_episodes(env, policy, seed, deterministic)
    p = float(r["success"].mean())
    return {
        "episodes": int(episodes),
        "stage": int(stage),
        "success_rate": p,
        "success_stderr": float(np.sqrt(p * (1 - p) / episodes)),
        "collision_rate": float(r["collision"].mean()),
        "truncation_rate": float(1.0 - r["success"].mean() - r["collision"].mean()),
        "mean_steps": float(r["length"].mean()),
    }
