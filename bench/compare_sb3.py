"""Peer comparison: Stable-Baselines3 PPO against mmrl's PPO on the same plane env, same budget.

    python bench/compare_sb3.py [--data DIR] [--budget 150] [--eval-every 3]

Both train on the same C++ batched env (64 environments), seed 0, one torch thread, 32 x 32
networks, with observation and reward normalization (SB3: VecNormalize). Two SB3
configurations (``--sb3``):

- ``stock``: SB3's PPO defaults (lr 3e-4, 10 epochs, minibatch 64, rollout 2048 samples =
  32 steps x 64 envs, lambda 0.95, clip 0.2) on the env's own action box, as a user would
  first try it;
- ``tuned``: mmrl's own hyperparameters (rollout 32 x 64, 8 epochs of 4 minibatches, lr 2e-3)
  and the same action rescaling to [-1, 1] that mmrl uses, so that the comparison is between
  implementations, not settings.

Every ``--eval-every`` seconds of training (evaluation time excluded) the deterministic
policy runs 300 fixed episodes; the script reports when each first reaches 90% success.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import mmrl
from mmrl.rl import ppo
from mmrl.rollout import evaluate_fast
from mmrl.tasks.plane import PlaneVectorEnv


def evaluate_plane(policy, db, **kwargs):
    return evaluate_fast(mmrl.get_task("plane"), db, policy, **kwargs)

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def sb3_adapter(env, rescale=True):
    """A Stable-Baselines3 VecEnv over an mmrl vector env (actions in [-1, 1] if rescale)."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import VecEnv

    low, high = env.single_action_space.low, env.single_action_space.high
    center, half = (high + low) / 2, (high - low) / 2
    if not rescale:
        center, half = np.zeros_like(low), np.ones_like(low)
    space = gym.spaces.Box(-1.0, 1.0, low.shape, np.float32) if rescale else env.single_action_space

    class Adapter(VecEnv):
        def __init__(self):
            super().__init__(env.num_envs, env.single_observation_space, space)
            self._actions = None

        def reset(self):
            obs, _ = env.reset(seed=0)
            return obs

        def step_async(self, actions):
            a = np.clip(actions, -1, 1) if rescale else np.clip(actions, low, high)
            self._actions = (center + half * a).astype(np.float32)

        def step_wait(self):
            obs, rew, term, trunc, info = env.step(self._actions)
            dones = term | trunc
            infos = [{} for _ in range(self.num_envs)]
            for i in np.flatnonzero(dones):
                infos[i] = {"terminal_observation": info["final_obs"][i],
                            "TimeLimit.truncated": bool(trunc[i] and not term[i]),
                            "is_success": bool(info["success"][i])}
            return obs, rew, dones, infos

        def close(self):
            pass

        def get_attr(self, name, indices=None):
            return [getattr(env, name)] * self.num_envs

        def set_attr(self, name, value, indices=None):
            pass

        def env_method(self, name, *args, indices=None, **kwargs):
            return [None] * self.num_envs

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * self.num_envs

    return Adapter(), center, half


class SB3Policy:
    def __init__(self, model, vecnorm, center, half):
        self.model, self.vecnorm, self.center, self.half = model, vecnorm, center, half

    def act(self, obs, deterministic=True):
        a, _ = self.model.predict(self.vecnorm.normalize_obs(obs), deterministic=deterministic)
        return (self.center + self.half * a).astype(np.float32)  # the env clips to its box


def first_reaching(curve, level):
    for wall, steps, succ in curve:
        if succ >= level:
            return wall, steps
    return None, None


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--budget", type=float, default=150.0, help="training seconds for each")
    ap.add_argument("--eval-every", type=float, default=3.0)
    ap.add_argument("--episodes", type=int, default=300)
    ap.add_argument("--sb3", choices=["stock", "tuned"], nargs="+", default=["stock", "tuned"])
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    db = mmrl.Database.from_bvh(args.data)
    _ = db.matcher
    print(f"{db!r}")

    # ours, in chunks of eval_every seconds (resume continues the same run)
    out = Path(tempfile.mkdtemp(prefix="mmrl-vs-sb3-"))
    env = PlaneVectorEnv(64, db=db)
    cfg = ppo.PPOConfig(seed=0, total_steps=10**12, progress=False, tensorboard=False)
    ours = []
    wall = 0.0
    while wall < args.budget:
        cfg.max_seconds = wall + args.eval_every
        res = ppo.train(env, cfg, out, resume=(out / "latest.pt").exists())
        wall = res.wall_s
        ev = evaluate_plane(ppo.load_policy(res.checkpoint), db, episodes=args.episodes)
        ours.append((wall, res.global_step, ev["success_rate"]))
        print(f"  mmrl  {wall:6.1f} s {res.global_step:>9,} steps  success {ev['success_rate']:.3f}", flush=True)
        if ev["success_rate"] >= 0.99:
            break

    # Stable-Baselines3
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    sb3_runs = {}
    for variant in args.sb3:
        env = PlaneVectorEnv(64, db=db)
        adapter, center, half = sb3_adapter(env, rescale=(variant == "tuned"))
        vec = VecNormalize(adapter, norm_obs=True, norm_reward=True, gamma=0.99)
        if variant == "tuned":
            hp = dict(n_steps=32, batch_size=512, n_epochs=8, learning_rate=2e-3)
        else:
            hp = dict(n_steps=32, batch_size=64, n_epochs=10, learning_rate=3e-4)
        model = PPO("MlpPolicy", vec, gamma=0.99, gae_lambda=0.95, clip_range=0.2, ent_coef=0.0, max_grad_norm=0.5,
                    seed=0, device="cpu", policy_kwargs=dict(net_arch=dict(pi=[32, 32], vf=[32, 32])), verbose=0,
                    **hp)
        curve = []
        wall, steps = 0.0, 0
        chunk = 64 * 32 * 4
        next_eval = args.eval_every
        while wall < args.budget:
            t0 = time.perf_counter()
            model.learn(total_timesteps=chunk, reset_num_timesteps=False)
            wall += time.perf_counter() - t0
            steps += chunk
            if wall >= next_eval or wall >= args.budget:
                next_eval = wall + args.eval_every
                vec.training = False
                ev = evaluate_plane(SB3Policy(model, vec, center, half), db, episodes=args.episodes)
                vec.training = True
                curve.append((wall, steps, ev["success_rate"]))
                print(f"  sb3-{variant:<5} {wall:6.1f} s {steps:>9,} steps  success {ev['success_rate']:.3f}", flush=True)
                if ev["success_rate"] >= 0.99:
                    break
        sb3_runs[variant] = curve

    print("\nfirst evaluation at >= 90% success (training wall time, env steps):")
    ow, os_ = first_reaching(ours, 0.9)
    print(f"  mmrl PPO:        {ow if ow is None else f'{ow:.1f} s, {os_:,} steps'}")
    for variant, curve in sb3_runs.items():
        sw, ss = first_reaching(curve, 0.9)
        print(f"  SB3 PPO {variant:<6}: {sw if sw is None else f'{sw:.1f} s, {ss:,} steps'}", end="")
        if ow and sw:
            print(f"  -> mmrl is {sw / ow:.1f}x sooner in wall time")
        elif ow:
            print(f"  -> did not reach 90% within {args.budget:.0f} s: mmrl is > {args.budget / ow:.1f}x sooner")
        else:
            print()


if __name__ == "__main__":
    main()
