"""The moving-obstacles task (paper, sections 4 and 5) and its 10-stage curriculum.

``mmrl/MovingObstacles-v0``: as ``mmrl/Plane-v0`` the policy writes the 12-d trajectory half of
a motion-matching query every 6 frames (0.2 s) and must bring the character within 0.5 m of a
target, now through 100 moving rectangles. The work is in C++ (``_core.ObstacleVecEnv``; the
header ``cpp/include/mmrl/obstacles_env.hpp`` documents every rule); this module holds spaces,
buffers, autoreset bookkeeping, infos and the curriculum.

- observation (529 floats, flat; ``OBSTACLE_LAYOUT``): the current and the previous 16 x 16
  binary sensor maps as (channel, row, col) in C order (channel 0 current; row along the
  character's forward Z, col along its left X; the 6 x 6 m square sits 1.5 m ahead of the
  root by default), then c_t (15 normalized pose features), then g_t (target (x, z) in the
  character frame, meters).
- action: the same 12-d box as the plane task.
- reward: ``exp(-|g_t|) + exp(-hits(a_t))`` (the second term off with ``hit_reward=False``),
  plus ``success_bonus`` on success (default 10: the paper says 10 in section 4 and no bonus
  in section 5).
  Mind the incentive: every surviving step earns up to 2, so under discounting (gamma 0.99)
  avoiding obstacles forever is worth far more than a bonus of 10; a short PPO run here
  learned to wander (episode length 15 -> 195 at stage 1). A bonus of a few hundred should
  remove the incentive (a 150k-step run with 200 did not wander but had not left stage 1 yet).
- termination: success, or collision of the body disc (``body_radius``) with any obstacle,
  both tested on every played frame. Truncation only at the ``max_steps`` safety cap (the
  paper has no step limit).

infos (SAME_STEP autoreset, masks ``_key``), where an episode ended: ``final_obs``, ``success``,
``collision``, ``episode_return``, ``episode_length``, ``episode_stage`` (the curriculum stage
label the episode ran with, 0 if none was set). ``env.last_hits`` holds every env's hits of
the last step.

Choices the paper leaves open, with the defaults of ``ObstaclesConfig``: rectangles are
rotated (angle uniform in [0, pi)), sides independently uniform in [0.25, 3] m, speeds
uniform in [0, stage max], directions uniform; centres bounce off the 20 x 20 m square's
border; body radius 0.25 m; no obstacle starts within 0.75 m of the root or 0.5 m of the
target.
"""
from __future__ import annotations

import os
from collections import deque
from dataclasses import asdict, dataclass, fields
from typing import Any, Dict, Optional, Union

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _core
from .database import Database
from .envs import _check_actions, resolve_database

#: Flat observation layout: (name, size) of each consecutive segment (``ObstacleActorCritic``'s format).
OBSTACLE_LAYOUT = tuple((str(name), int(size)) for name, size in _core.ObstacleVecEnv.layout)
#: Shape of the "maps" segment: (channel, row, col), channel 0 current, 1 previous.
OBSTACLE_MAP_SHAPE = (2, _core.OBSTACLE_MAP_SIDE, _core.OBSTACLE_MAP_SIDE)
#: [start, stop) of the binary maps in the flat observation (``PPOConfig.obs_norm_exclude``).
OBSTACLE_MAP_RANGE = (0, 2 * _core.OBSTACLE_MAP_SIDE ** 2)


def obstacle_policy_factory(envs=None):
    """``policy_factory(obs_dim, act_dim)`` for ``ppo.train``: the paper's CNN actor-critic
    (``mmrl.networks.ObstacleActorCritic``) with this env's observation layout."""
    layout = getattr(envs, "layout", OBSTACLE_LAYOUT)
    map_shape = getattr(envs, "map_shape", OBSTACLE_MAP_SHAPE)

    def factory(obs_dim: int, act_dim: int):
        if obs_dim != sum(size for _, size in layout):
            raise ValueError(f"obstacle_policy_factory: obs_dim {obs_dim} does not match the layout {layout}")
        from .networks import ObstacleActorCritic

        return ObstacleActorCritic(act_dim, layout=layout, map_shape=map_shape)

    return factory


@dataclass
class ObstaclesConfig:
    """Numbers of the moving-obstacles task. The defaults are the paper's hardest stage."""

    frames_per_step: int = 6
    """Frames played per RL step (6 = 0.2 s at 30 fps)."""
    target_half_extent: float = 5.0
    """Stage before any ``set_stage``: targets uniform in a square of side 2 * this (meters)."""
    obstacle_max_speed: float = 0.5
    """Stage before any ``set_stage``: obstacle speeds uniform in [0, this] m/s."""
    speed_cap: float = 2.0
    """The largest max speed (m/s) ``set_stage`` accepts; sizes the collision grid's margin."""
    min_target_distance: float = 0.6
    """Targets closer than this (meters) to the start are redrawn."""
    success_radius: float = 0.5
    """Reaching within this distance (meters) of the target is success."""
    success_bonus: float = 10.0
    """Reward added on success. The paper says 10 (section 4) and none (section 5); 10 here."""
    hit_reward: bool = True
    """Add exp(-hits(a_t)) to the reward (False: the ``--no-hit-reward`` ablation)."""
    hit_weight: float = 1.0
    """The hit term is ``hit_weight * exp(-hits)`` (the paper: 1)."""
    hit_penalty: bool = False
    """Subtract ``hit_weight`` from the hit term, making it a penalty that is 0 for a clear
    action. The paper's form pays up to 1 for every surviving step, which (with the distance
    term) is what makes a small success bonus teach wandering."""
    hit_radius: float = 0.0
    """A trajectory point counts as a hit when a disc of this radius (meters) around it overlaps
    an obstacle; 0 is the paper's point test."""
    hit_lookahead: bool = False
    """Test each trajectory point against the obstacles where they will be at that point's time
    (10 / 20 / 30 frames ahead, constant velocity with bounces); False is the paper's test
    against the current positions."""
    hit_played: bool = False
    """Test the future trajectory of the frame the step matched (the path the clip plays, in
    the character frame at the step's start) instead of the action's; False is the paper's
    test of the action. ``env_state``'s hit points follow the test; ``mmrl render`` draws the
    action's points either way."""
    max_steps: int = 1500
    """Safety cap on the episode length (truncation; 1500 steps = 300 s). The paper has none."""
    action_limit_std: float = 3.0
    """Half-width of the action box in standard deviations of each normalized trajectory feature."""
    random_heading: bool = True
    """Start with a uniformly random heading (else facing +Z)."""
    num_obstacles: int = 100
    """Rectangles per environment."""
    obstacle_square_half: float = 10.0
    """Obstacle centres start uniform in, and bounce inside, a square of side 2 * this (meters) around the start."""
    obstacle_min_side: float = 0.25
    """Each rectangle side is uniform in [min_side, max_side] meters."""
    obstacle_max_side: float = 3.0
    """Largest rectangle side (meters); the paper's 3 x 3 m maximum."""
    body_radius: float = 0.25
    """Collision disc around the root (meters)."""
    start_clearance: float = 0.5
    """No obstacle starts within body_radius + this (meters) of the character."""
    target_clearance: float = 0.5
    """No obstacle starts within this (meters) of the target."""
    sensor_size: float = 6.0
    """Side of the square sensor map (meters), 16 x 16 point sensors."""
    sensor_forward: float = 1.5
    """Centre of the sensor square ahead of the root (meters); 0 centres it on the character."""
    previous_map_lag: int = 1
    """The observation's second map is the one read this many RL steps ago (1: the paper's
    previous step). At 0.5 m/s an obstacle moves 0.1 m in one step, under the 0.375 m sensor
    pitch; a longer lag makes its motion show."""
    grid_cell_size: float = 1.5
    """Cell side (meters) of the uniform grid used for sensors, hits and collisions."""

    def to_core(self) -> "_core.ObstacleTaskConfig":
        c = _core.ObstacleTaskConfig()
        for f in fields(self):
            setattr(c, f.name, getattr(self, f.name))
        return c


#: ``mmrl train obstacles --preset NAME``: option overrides (task options and PPOConfig fields).
#: "paper" is the paper's task as written (success bonus 10, the hit term exp(-hits) on the
#: three points at the obstacles' current positions). "mmrl" is what trains best here
#: (docs/obstacles.md): a success bonus of 1000 (with 10, and even 300, the agent learns to
#: wander), the hit term as a penalty of weight 10 that is 0 for a clear action, tested with
#: the body's radius against where each obstacle will be at the point's time, and a linearly
#: annealed learning rate.
OBSTACLE_PRESETS: Dict[str, Dict[str, Any]] = {
    "paper": {},
    "mmrl": {"success_bonus": 1000.0, "hit_penalty": True, "hit_weight": 10.0, "hit_radius": 0.25,
             "hit_lookahead": True, "anneal_lr": True},
}


def _config(config: Optional[ObstaclesConfig], overrides: Dict[str, Any]) -> ObstaclesConfig:
    cfg = ObstaclesConfig(**asdict(config)) if config is not None else ObstaclesConfig()
    for k, v in overrides.items():
        if not hasattr(cfg, k):
            raise TypeError(f"unknown moving-obstacles option {k!r}; options are {[f.name for f in fields(cfg)]}")
        setattr(cfg, k, v)
    return cfg


def _observation_space() -> gym.spaces.Box:
    n_map = 2 * _core.OBSTACLE_MAP_SIDE ** 2
    rest = _core.ObstacleVecEnv.obs_dim - n_map
    low = np.concatenate([np.zeros(n_map, np.float32), np.full(rest, -np.inf, np.float32)])
    high = np.concatenate([np.ones(n_map, np.float32), np.full(rest, np.inf, np.float32)])
    return gym.spaces.Box(low, high, dtype=np.float32)


class ObstaclesVectorEnv(VectorEnv):
    """N moving-obstacles characters stepped together in C++ (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": [], "render_fps": 30}

    def __init__(self, num_envs: int = 64, *, db: Union[Database, str, os.PathLike, None] = None,
                 data=None, config: Optional[ObstaclesConfig] = None, num_threads: int = 0,
                 render_mode: Optional[str] = None, **overrides):
        if render_mode is not None:
            raise ValueError(f"render_mode: this env renders through mmrl render, got {render_mode!r}")
        self.db = resolve_database(db, data)
        self.config = _config(config, overrides)
        self.num_envs = int(num_envs)
        self.render_mode = None
        self._core = _core.ObstacleVecEnv(self.db._db, self.db.matcher, self.num_envs, self.config.to_core(),
                                          num_threads)
        obs_dim, act_dim = _core.ObstacleVecEnv.obs_dim, _core.ObstacleVecEnv.action_dim
        self.layout = OBSTACLE_LAYOUT
        self.map_shape = OBSTACLE_MAP_SHAPE
        self.single_observation_space = _observation_space()
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
        self._collision = np.zeros(n, np.uint8)
        self._hits = np.zeros(n, np.int32)
        self._ep_return = np.zeros(n, np.float32)
        self._ep_length = np.zeros(n, np.int32)
        # Curriculum bookkeeping: the stage label each env's episode runs with, the label of
        # the next resets, and (label, success) of episodes finished since the last drain.
        self._stage_label = 0
        self._env_stage = np.zeros(n, np.int32)
        self._finished_stage: list = []
        self._finished_success: list = []
        self._seeded = False

    # -- curriculum -------------------------------------------------------------------------
    def set_stage(self, max_speed: float, target_half_extent: float, label: int = 0) -> None:
        """Obstacle max speed (m/s) and target square half-extent (m) for each env's next reset.

        ``label`` (e.g. the curriculum stage number) is reported as ``episode_stage`` for
        episodes that start after this call.
        """
        self._core.set_stage(float(max_speed), float(target_half_extent))
        self._stage_label = int(label)

    @property
    def stage(self) -> tuple:
        """(max_speed, target_half_extent) applied at the next resets."""
        return tuple(self._core.stage)

    def pop_finished_episodes(self) -> tuple:
        """(stage labels, successes) of the episodes finished since the last call, as arrays."""
        stages = np.asarray(self._finished_stage, np.int32)
        success = np.asarray(self._finished_success, bool)
        self._finished_stage, self._finished_success = [], []
        return stages, success

    # -- gymnasium ---------------------------------------------------------------------------
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
        self._env_stage[:] = self._stage_label
        return self._obs.copy(), {}

    def step(self, actions):
        a = _check_actions(actions, (self.num_envs, _core.ObstacleVecEnv.action_dim))
        self._core.step(a, self._obs, self._rewards, self._terminated, self._truncated, self._success,
                        self._collision, self._hits, self._final_obs, self._ep_return, self._ep_length)
        terminated = self._terminated.astype(bool)
        truncated = self._truncated.astype(bool)
        infos: Dict[str, Any] = {}
        done = terminated | truncated
        if done.any():
            success = self._success.astype(bool)
            infos["final_obs"] = np.where(done[:, None], self._final_obs, 0.0).astype(np.float32)
            infos["success"] = success
            infos["collision"] = self._collision.astype(bool)
            infos["episode_return"] = np.where(done, self._ep_return, 0.0).astype(np.float32)
            infos["episode_length"] = np.where(done, self._ep_length, 0).astype(np.int32)
            infos["episode_stage"] = np.where(done, self._env_stage, 0).astype(np.int32)
            for key in ("final_obs", "success", "collision", "episode_return", "episode_length", "episode_stage"):
                infos["_" + key] = done.copy()
            self._finished_stage.extend(self._env_stage[done].tolist())
            self._finished_success.extend(success[done].tolist())
            self._env_stage[done] = self._stage_label
        return self._obs.copy(), self._rewards.copy(), terminated, truncated, infos

    @property
    def last_hits(self) -> np.ndarray:
        """hits(a_t) of every env's last action (0..3)."""
        return self._hits.copy()

    # -- inspection (rendering, tests, evaluation) ---------------------------------------------
    def env_state(self, i: int) -> dict:
        """World-space state of env i: root x, z, yaw, frame, target, stage, last hit points."""
        return self._core.state(i)

    def obstacles(self, i: int) -> dict:
        """Env i's obstacles: centres (n,2), half_sizes (n,2), angles (n), velocities (n,2); world (x, z)."""
        return self._core.obstacles(i)

    def action_hits(self, i: int, action: np.ndarray):
        """For env i's current state: (hits, points (3, 2) world x/z, inside (3,) bool) of a
        12-d action's three future trajectory positions (the hit reward's count)."""
        a = np.ascontiguousarray(action, dtype=np.float32).reshape(-1)
        return self._core.action_hits(int(i), a)

    def collides(self, i: int, x: float, z: float) -> bool:
        """Whether the body disc at world (x, z) overlaps one of env i's obstacles."""
        return bool(self._core.collides(int(i), float(x), float(z)))

    def sensor_map(self, i: int, previous: bool = False) -> np.ndarray:
        """Env i's current (or previous) sensor map, uint8 (16, 16) [row (forward)][col (left)]."""
        return self._core.sensor_map(i, previous)

    def sensor_positions(self, i: int) -> np.ndarray:
        """World (x, z) of env i's sensors, (16, 16, 2)."""
        return self._core.sensor_positions(i)

    def current_frames(self) -> np.ndarray:
        """Each env's current database frame (int64, N)."""
        return np.array([self._core.state(i)["frame"] for i in range(self.num_envs)], np.int64)

    def observe(self, i: int) -> np.ndarray:
        """Env i's current observation (529,), also written to the env's observation buffer."""
        out = self._core.observe(i)
        self._obs[i] = out
        return out

    def set_target(self, i: int, x: float, z: float) -> np.ndarray:
        """Move env i's target (world meters); returns its new observation."""
        self._core.set_target(i, float(x), float(z))
        return self.observe(i)


class ObstaclesEnv(gym.Env):
    """A single moving-obstacles character (the same C++ core with one environment)."""

    metadata = {"render_modes": [], "render_fps": 30}

    def __init__(self, *, db=None, data=None, config: Optional[ObstaclesConfig] = None,
                 render_mode: Optional[str] = None, **overrides):
        self._vec = ObstaclesVectorEnv(1, db=db, data=data, config=config, num_threads=1, render_mode=render_mode,
                                       **overrides)
        self.db = self._vec.db
        self.config = self._vec.config
        self.render_mode = None
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
        info: Dict[str, Any] = {"hits": int(self._vec._hits[0])}
        if term[0] or trunc[0]:
            obs = infos["final_obs"]
            info.update(success=bool(infos["success"][0]), collision=bool(infos["collision"][0]),
                        episode_return=float(infos["episode_return"][0]),
                        episode_length=int(infos["episode_length"][0]))
        return obs[0].copy(), float(r[0]), bool(term[0]), bool(trunc[0]), info

    def set_stage(self, max_speed: float, target_half_extent: float, label: int = 0) -> None:
        self._vec.set_stage(max_speed, target_half_extent, label)

    def env_state(self) -> dict:
        return self._vec.env_state(0)

    def obstacles(self) -> dict:
        return self._vec.obstacles(0)


class Curriculum:
    """The paper's obstacle curriculum, as a PPO trainer callback.

    Stage k (1..num_stages) has obstacle max speed and target square half-extent linearly
    interpolated from ``first`` (stage 1: static obstacles, targets in a 5 x 5 m square) to
    ``last`` (stage 10: 0.5 m/s, 10 x 10 m). The stage is applied to the envs at once and each
    env picks it up at its next reset.

    Advancing: after each PPO iteration (``on_iteration``), if at least ``window`` episodes
    that *ran at the current stage* have finished, and the success ratio of the last
    ``window`` of them (across all envs) exceeds ``threshold`` (40%), the next stage starts
    and the window is cleared. Episodes still running with the previous stage are ignored.
    At most one advance per iteration. ``enabled=False`` (``--no-curriculum``) starts and
    stays at the last stage.

    Completion: the last stage is *passed* (``complete``, and every stage with it) the first
    time its window is full and exceeds the threshold; ``complete_step`` is the env step of
    that iteration when the trainer's stats give it. Training goes on at the last stage.

    ``on_iteration(stats)`` returns ``{"curriculum_stage": k, "curriculum_complete": 0 or 1}``:
    the stage after this iteration's update (the one the next iteration trains on).
    """

    def __init__(self, envs=None, *, num_stages: int = 10, first=(0.0, 2.5), last=(0.5, 5.0),
                 threshold: float = 0.4, window: int = 200, enabled: bool = True):
        if num_stages < 1:
            raise ValueError(f"num_stages must be >= 1, got {num_stages}")
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        if not 0.0 <= threshold < 1.0:
            raise ValueError(f"threshold must be in [0, 1), got {threshold}")
        self.num_stages = int(num_stages)
        self.first = (float(first[0]), float(first[1]))
        self.last = (float(last[0]), float(last[1]))
        self.threshold = float(threshold)
        self.window = int(window)
        self.enabled = bool(enabled)
        self.envs = getattr(envs, "unwrapped", envs)
        self.stage = 1 if self.enabled else self.num_stages
        self.complete = False
        self.complete_step: Optional[int] = None
        self._recent: deque = deque(maxlen=self.window)
        self._apply()

    def stage_params(self, stage: int) -> tuple:
        """(max_speed m/s, target_half_extent m) of stage 1..num_stages."""
        if not 1 <= stage <= self.num_stages:
            raise ValueError(f"stage must be in 1..{self.num_stages}, got {stage}")
        t = 0.0 if self.num_stages == 1 else (stage - 1) / (self.num_stages - 1)
        return (self.first[0] + t * (self.last[0] - self.first[0]),
                self.first[1] + t * (self.last[1] - self.first[1]))

    def _apply(self) -> None:
        if self.envs is not None:
            self.envs.set_stage(*self.stage_params(self.stage), label=self.stage)

    @property
    def success_ratio(self) -> float:
        """Success ratio of the current window (NaN when empty)."""
        return float(np.mean(self._recent)) if self._recent else float("nan")

    def record(self, success, stages=None) -> None:
        """Add finished episodes (successes, and the stage each ran with if known)."""
        success = np.asarray(success, bool).reshape(-1)
        if stages is not None:
            success = success[np.asarray(stages).reshape(-1) == self.stage]
        self._recent.extend(success.tolist())

    def advance_if_ready(self) -> bool:
        """Go to the next stage if the window is full and its success ratio exceeds the
        threshold (at the last stage: mark the curriculum complete and stay)."""
        if len(self._recent) < self.window or not self.success_ratio > self.threshold:
            return False
        if self.stage >= self.num_stages:
            self.complete = True
            return False
        if not self.enabled:
            return False
        self.stage += 1
        self._recent.clear()
        self._apply()
        return True

    def on_iteration(self, stats: Optional[dict] = None) -> dict:
        """Trainer hook: record the iteration's finished episodes, maybe advance, report the stage.

        With envs attached, episodes come from ``envs.pop_finished_episodes()`` (which knows the
        stage each ran with); otherwise from the trainer's ``stats["episode_data"]["success"]``.
        """
        if self.envs is not None and hasattr(self.envs, "pop_finished_episodes"):
            stages, success = self.envs.pop_finished_episodes()
            self.record(success, stages)
        elif stats is not None and isinstance(stats.get("episode_data"), dict):
            self.record(stats["episode_data"].get("success", ()))
        was_complete = self.complete
        self.advance_if_ready()
        if self.complete and not was_complete and stats is not None and "step" in stats:
            self.complete_step = int(stats["step"])
        return {"curriculum_stage": self.stage, "curriculum_complete": int(self.complete)}

    def state_dict(self) -> dict:
        return {"stage": self.stage, "recent": list(self._recent), "enabled": self.enabled,
                "complete": self.complete, "complete_step": self.complete_step}

    def load_state_dict(self, state: dict) -> None:
        stage = int(state["stage"])
        if not 1 <= stage <= self.num_stages:
            raise ValueError(f"curriculum state: stage {stage} outside 1..{self.num_stages}")
        self.stage = stage
        self.enabled = bool(state.get("enabled", self.enabled))
        self.complete = bool(state.get("complete", False))
        self.complete_step = state.get("complete_step")
        self._recent = deque((bool(s) for s in state.get("recent", ())), maxlen=self.window)
        if self.envs is not None and hasattr(self.envs, "pop_finished_episodes"):
            self.envs.pop_finished_episodes()  # episodes of the old stage setting
        self._apply()


def register_envs() -> None:
    """Register ``mmrl/MovingObstacles-v0`` with gymnasium (idempotent)."""
    if "mmrl/MovingObstacles-v0" not in gym.registry:
        gym.register(id="mmrl/MovingObstacles-v0", entry_point="mmrl.obstacles:ObstaclesEnv",
                     vector_entry_point="mmrl.obstacles:ObstaclesVectorEnv")


register_envs()
