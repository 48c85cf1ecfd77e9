"""Gymnasium environments over the C++ batched cores.

``mmrl/Plane-v0`` (paper, section 3): the policy writes the 12-d trajectory half of a
motion-matching query every 6 frames (0.2 s) and must bring the character within 0.5 m of a
random target.

- observation: ``[c_t (15), g_t (2)]``: the current frame's pose features in the database's
  normalized units, and the target's (x, z) in the character frame in meters (X left, Z
  forward);
- action: the trajectory features (positions and facing directions at +10/+20/+30 frames)
  in normalized units, clipped to ``mean +- action_limit_std * std`` per dimension over the
  database's valid frames (the action space's box);
- reward: ``exp(-|g_t|)`` per step plus ``success_bonus`` (1000) on success, which
  terminates the episode; success is tested on every played frame. ``max_steps`` (100 steps
  = 20 s) truncates.

The vector env (``gymnasium.make_vec("mmrl/Plane-v0", num_envs=N)``) steps all N characters
in one C++ call with the GIL released and autoresets in SAME_STEP mode: the final
observation of a finished episode is in ``infos["final_obs"]``. ``infos["success"]``,
``infos["episode_return"]`` and ``infos["episode_length"]`` (with ``_``-prefixed masks) are
set where an episode ended. Seeding: ``reset(seed=s)`` gives environment i its own random
stream derived from (s, i).
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, fields
from typing import Any, Dict, Optional, Sequence, Union

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _core
from .database import Database

_DEFAULT_DB: Optional[Database] = None


def default_database() -> Database:
    """The package's synthetic locomotion database (generated once into the cache)."""
    global _DEFAULT_DB
    if _DEFAULT_DB is None:
        from . import synth

        _DEFAULT_DB = Database.from_bvh(synth.default_dataset_dir())
    return _DEFAULT_DB


def resolve_database(db: Union[Database, str, os.PathLike, None] = None,
                     data: Union[str, os.PathLike, Sequence[Union[str, os.PathLike]], None] = None,
                     mirror: bool = False) -> Database:
    """A Database from an object, a saved ``.npz``, BVH files/directories, or the default."""
    if isinstance(db, Database):
        return db
    if db is not None:
        return Database.load(db)
    if data is not None:
        return Database.from_bvh(data, mirror=mirror)
    return default_database()


@dataclass
class PlaneConfig:
    """Numbers of the plane task (all configurable)."""

    frames_per_step: int = 6
    """Frames played per RL step (6 = 0.2 s at 30 fps)."""
    target_half_extent: float = 5.0
    """Targets are uniform in a square of side 2 * this (meters) around the start."""
    min_target_distance: float = 0.6
    """Targets closer than this (meters) to the start are redrawn, so no episode starts solved."""
    success_radius: float = 0.5
    """Reaching within this distance (meters) of the target is success."""
    success_bonus: float = 1000.0
    """Reward added on success."""
    max_steps: int = 100
    """Steps before truncation (100 steps = 20 s)."""
    action_limit_std: float = 3.0
    """Half-width of the action box in standard deviations of each normalized trajectory feature."""
    random_heading: bool = True
    """Start with a uniformly random heading (else facing +Z)."""

    def to_core(self) -> "_core.TargetTaskConfig":
        c = _core.TargetTaskConfig()
        for f in fields(self):
            setattr(c, f.name, getattr(self, f.name))
        return c


def _config(config: Optional[PlaneConfig], overrides: Dict[str, Any]) -> PlaneConfig:
    cfg = PlaneConfig(**asdict(config)) if config is not None else PlaneConfig()
    for k, v in overrides.items():
        if not hasattr(cfg, k):
            raise TypeError(f"unknown plane-task option {k!r}; options are {[f.name for f in fields(PlaneConfig)]}")
        setattr(cfg, k, v)
    return cfg


def _check_actions(actions, shape) -> np.ndarray:
    a = np.asarray(actions)
    if a.shape != shape:
        raise ValueError(f"actions: expected shape {shape}, got {a.shape}")
    if not np.issubdtype(a.dtype, np.floating):
        raise TypeError(f"actions: expected a float array, got dtype {a.dtype}")
    a = np.ascontiguousarray(a, dtype=np.float32)
    if not np.isfinite(a).all():
        raise ValueError("actions: contains NaN or inf")
    return a


class PlaneVectorEnv(VectorEnv):
    """N plane-task characters stepped together in C++ (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, num_envs: int = 64, *, db: Union[Database, str, os.PathLike, None] = None,
                 data=None, config: Optional[PlaneConfig] = None, num_threads: int = 0,
                 render_mode: Optional[str] = None, **overrides):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.db = resolve_database(db, data)
        self.config = _config(config, overrides)
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self._core = _core.PlaneVecEnv(self.db._db, self.db.matcher, self.num_envs, self.config.to_core(), num_threads)
        obs_dim, act_dim = _core.PlaneVecEnv.obs_dim, _core.PlaneVecEnv.action_dim
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        self.single_action_space = gym.spaces.Box(self._core.action_low, self._core.action_high, (act_dim,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n = self.num_envs
        self._obs = np.zeros((n, obs_dim), np.float32)
        self._final_obs = np.zeros((n, obs_dim), np.float32)
        self._rewards = np.zeros(n, np.float32)
        self._terminated = np.zeros(n, np.uint8)
        self._truncated = np.zeros(n, np.uint8)
        self._success = np.zeros(n, np.uint8)
        self._ep_return = np.zeros(n, np.float32)
        self._ep_length = np.zeros(n, np.int32)
        self._seeded = False

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is None and not self._seeded:
            seed = int(np.random.SeedSequence().generate_state(1, np.uint64)[0])
        if seed is not None:
            if isinstance(seed, (list, tuple)):
                raise TypeError("seed: give one int; environment i derives its stream from (seed, i)")
            self._core.reset(int(seed) & 0xFFFFFFFFFFFFFFFF, self._obs)
            self._seeded = True
        else:
            for i in range(self.num_envs):
                self._core.reset_env(i, self._obs)
        return self._obs.copy(), {}

    def step(self, actions):
        a = _check_actions(actions, (self.num_envs, _core.PlaneVecEnv.action_dim))
        self._core.step(a, self._obs, self._rewards, self._terminated, self._truncated, self._success,
                        self._final_obs, self._ep_return, self._ep_length)
        terminated = self._terminated.astype(bool)
        truncated = self._truncated.astype(bool)
        infos: Dict[str, Any] = {}
        done = terminated | truncated
        if done.any():
            infos["final_obs"] = np.where(done[:, None], self._final_obs, 0.0).astype(np.float32)
            infos["_final_obs"] = done.copy()
            infos["success"] = self._success.astype(bool)
            infos["_success"] = done.copy()
            infos["episode_return"] = np.where(done, self._ep_return, 0.0).astype(np.float32)
            infos["_episode_return"] = done.copy()
            infos["episode_length"] = np.where(done, self._ep_length, 0).astype(np.int32)
            infos["_episode_length"] = done.copy()
        return self._obs.copy(), self._rewards.copy(), terminated, truncated, infos

    def env_state(self, i: int) -> dict:
        """World-space state of environment i: root x, z, yaw, database frame, target."""
        return self._core.state(i)

    def current_frames(self) -> np.ndarray:
        """Each environment's current database frame (int64, N)."""
        out = np.empty(self.num_envs, np.int64)
        self._core.current_frames(out)
        return out

    def set_target(self, i: int, x: float, z: float) -> np.ndarray:
        """Move environment i's target (world meters); returns its new observation."""
        self._core.set_target(i, float(x), float(z))
        return self.observe(i)

    def observe(self, i: int) -> np.ndarray:
        """Environment i's current observation (17,)."""
        out = np.empty(_core.PlaneVecEnv.obs_dim, np.float32)
        self._core.observe(i, out)
        self._obs[i] = out
        return out

    def render(self):
        from .render import render_topdown

        return render_topdown([self.env_state(i) for i in range(self.num_envs)])


class PlaneEnv(gym.Env):
    """A single plane-task character (the same C++ core with one environment)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, *, db=None, data=None, config: Optional[PlaneConfig] = None,
                 render_mode: Optional[str] = None, **overrides):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self._vec = PlaneVectorEnv(1, db=db, data=data, config=config, num_threads=1, **overrides)
        self.db = self._vec.db
        self.config = self._vec.config
        self.render_mode = render_mode
        self.observation_space = self._vec.single_observation_space
        self.action_space = self._vec.single_action_space

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        if seed is None and not self._vec._seeded:
            seed = int(self.np_random.integers(0, 2**63 - 1))
        obs, _ = self._vec.reset(seed=seed)
        return obs[0], {}

    def step(self, action):
        a = _check_actions(action, self.action_space.shape)
        obs, r, term, trunc, infos = self._vec.step(a[None])
        info: Dict[str, Any] = {}
        if term[0] or trunc[0]:
            obs = infos["final_obs"]
            info = {"success": bool(infos["success"][0]), "episode_return": float(infos["episode_return"][0]),
                    "episode_length": int(infos["episode_length"][0])}
        return obs[0].copy(), float(r[0]), bool(term[0]), bool(trunc[0]), info

    def env_state(self) -> dict:
        return self._vec.env_state(0)

    def render(self):
        from .render import render_state

        return render_state(self.db, self._vec.env_state(0))


def register_envs() -> None:
    """Register ``mmrl/Plane-v0`` with gymnasium (idempotent)."""
    if "mmrl/Plane-v0" not in gym.registry:
        gym.register(id="mmrl/Plane-v0", entry_point="mmrl.envs:PlaneEnv",
                     vector_entry_point="mmrl.envs:PlaneVectorEnv")
