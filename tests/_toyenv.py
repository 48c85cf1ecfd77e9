"""A tiny numpy point-mass target-reaching vector env, shaped like the plane task.

It exists so PPO can be tested without the C++ core or the motion database:

- the agent is a point on the ground plane; the target is uniform in a square
  (default 10 x 10 m) around the start;
- observation: the target relative to the agent (2, meters), the previous
  displacement (2, meters) and ``extra_obs_dims`` entries of pure noise
  (distractors standing in for the 15 pose features);
- action: a displacement in meters per step, scaled by ``step_size`` from the
  box [-1, 1]; ``extra_act_dims`` more action entries are ignored (standing in
  for the query dimensions that do not move the character directly);
- with ``max_turn`` (radians per step) the agent has a heading, observes the
  target in its own frame, and turns toward the commanded direction by at
  most ``max_turn`` before moving, so a target behind it costs extra steps
  (like the motion data, which barely turns in place);
- reward: exp(-distance) every step plus ``success_bonus`` (default 1000) when
  the agent comes within ``success_radius`` of the target, which terminates
  the episode; ``max_steps`` truncates it;
- SAME_STEP autoreset with ``infos["final_obs"]`` and ``infos["success"]``,
  like the C++ envs.
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space


class PointMassTargetVecEnv(VectorEnv):
    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 16,
        *,
        area: float = 10.0,
        step_size: float = 0.5,
        success_radius: float = 0.5,
        success_bonus: float = 1000.0,
        max_steps: int = 50,
        extra_obs_dims: int = 0,
        extra_act_dims: int = 0,
        max_turn: float | None = None,
    ):
        self.num_envs = num_envs
        self.area = area
        self.step_size = step_size
        self.success_radius = success_radius
        self.success_bonus = success_bonus
        self.max_steps = max_steps
        self.extra_obs_dims = extra_obs_dims
        self.max_turn = max_turn
        obs_dim = 4 + extra_obs_dims
        act_dim = 2 + extra_act_dims
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (act_dim,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rng = np.random.default_rng()
        self._target = np.zeros((num_envs, 2))  # relative to the agent, meters
        self._last_move = np.zeros((num_envs, 2))
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._obs = np.zeros((num_envs, obs_dim), dtype=np.float32)

    def _reset_envs(self, mask: np.ndarray) -> None:
        n = int(mask.sum())
        self._target[mask] = self._rng.uniform(-self.area / 2, self.area / 2, (n, 2))
        self._last_move[mask] = 0.0
        self._steps[mask] = 0

    def _write_obs(self) -> np.ndarray:
        self._obs[:, 0:2] = self._target
        self._obs[:, 2:4] = self._last_move
        if self.extra_obs_dims:
            self._obs[:, 4:] = self._rng.standard_normal((self.num_envs, self.extra_obs_dims))
        return self._obs.copy()

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._reset_envs(np.ones(self.num_envs, dtype=bool))
        return self._write_obs(), {}

    def step(self, actions):
        actions = np.asarray(actions, dtype=np.float64)
        if not np.isfinite(actions).all():
            raise ValueError("PointMassTargetVecEnv.step: actions contain NaN or inf")
        move = np.clip(actions[:, :2], -1.0, 1.0) * self.step_size
        if self.max_turn is not None:
            # The command is in the agent's frame (x forward, y left): turn
            # toward it by at most max_turn, move forward by its length, and
            # express the target in the new frame.
            turn = np.clip(np.arctan2(move[:, 1], move[:, 0]), -self.max_turn, self.max_turn)
            cos, sin = np.cos(turn), np.sin(turn)
            x, y = self._target[:, 0].copy(), self._target[:, 1].copy()
            self._target[:, 0] = cos * x + sin * y
            self._target[:, 1] = -sin * x + cos * y
            move = np.stack([np.linalg.norm(move, axis=1), np.zeros(self.num_envs)], axis=1)
        self._target -= move
        self._last_move[:] = move
        self._steps += 1
        dist = np.linalg.norm(self._target, axis=1)
        terminated = dist < self.success_radius
        truncated = (self._steps >= self.max_steps) & ~terminated
        rewards = np.exp(-dist) + self.success_bonus * terminated
        done = terminated | truncated
        infos = {}
        if done.any():
            final_obs = self._write_obs()
            infos = {
                "final_obs": final_obs,
                "_final_obs": done.copy(),
                "success": terminated.copy(),
                "_success": done.copy(),
            }
            self._reset_envs(done)
        obs = self._write_obs()
        return obs, rewards.astype(np.float32), terminated, truncated, infos


def quiet_config(total_steps: int = 8192, **overrides):
    """A PPOConfig for tests: no progress bar, no TensorBoard, no periodic checkpoints."""
    from mmrl.rl.ppo import PPOConfig

    fields = dict(total_steps=total_steps, num_steps=32, progress=False, tensorboard=False,
                  checkpoint_interval_steps=10**9)
    fields.update(overrides)
    return PPOConfig(**fields)


def read_rows(path) -> list:
    """metrics.csv as a list of dicts (strings)."""
    import csv

    with open(path, newline="") as file:
        return list(csv.DictReader(file))
