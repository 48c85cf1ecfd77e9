"""The moving-obstacles task (paper, sections 4 and 5) and its 10-stage curriculum.

``mmrl/MovingObstacles-v0``: as ``mmrl/Plane-v0`` the policy writes the 12-d trajectory half of
a motion-matching query every 6 frames (0.2 s) and must bring the character within 0.5 m of a
target, now through 100 moving rectangles. The work is in C++ (``_core.ObstacleVecEnv``; its header
documents every rule); this module declares the task: config, env, network, presets, the
curriculum callback and the full path's scene (obstacles, sensor maps, hit points).

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

from collections import deque
from dataclasses import field
from typing import Any, Dict, Mapping, Optional

import gymnasium as gym
import numpy as np

from .. import _core
from .base import SingleEnv, TargetVectorEnv, Task, TaskConfig, TaskFlag
from .curriculum import Curriculum, stage_params
from .options import task_options

#: Flat observation layout: (name, size) of each consecutive segment (``ObstacleActorCritic``'s
#: format); with ``request_groups`` an env appends the request's code (its ``observation_layout``).
OBSTACLE_LAYOUT = tuple((str(name), int(size)) for name, size in _core.ObstacleVecEnv.layout)
#: Shape of the "maps" segment: (channel, row, col), channel 0 current, 1 previous.
OBSTACLE_MAP_SHAPE = (2, _core.OBSTACLE_MAP_SIDE, _core.OBSTACLE_MAP_SIDE)
#: [start, stop) of the binary maps in the flat observation (``PPOConfig.obs_norm_exclude``).
OBSTACLE_MAP_RANGE = (0, 2 * _core.OBSTACLE_MAP_SIDE ** 2)


@task_options(_core.ObstacleTaskConfig)
class ObstaclesConfig(TaskConfig):
    """Numbers of the moving-obstacles task (its options: cpp/include/mmrl/tasks/obstacles.hpp's
    table). The defaults are the paper's hardest stage."""

    task_label = "moving-obstacles"
    training_only = ("train_path_filter",)
    policy_inputs = TaskConfig.policy_inputs + ("sensor_size", "sensor_forward")

    train_path_filter: bool = field(default=True, metadata={"doc": (
        "Whether the training envs run the collision-aware search too; false trains without it and keeps "
        "path_filter for everything after training (eval, render, play, export). The C++ core never sees it.")})


#: ``mmrl train obstacles --preset NAME``: option overrides (task options and PPOConfig fields).
#: "paper" is the paper's task as written (success bonus 10, the hit term exp(-hits) on the
#: three points at the obstacles' current positions). "mmrl" is what trains best here
#: (docs/obstacles.md): a success bonus of 1000 (with 10, and even 300, the agent learns to
#: wander), the hit term as a penalty of weight 10 that is 0 for a clear action, tested with
#: the body's radius against where each obstacle will be at the point's time, and a linearly
#: annealed learning rate. ``mmrl train obstacles`` uses "mmrl" unless told otherwise.
_MMRL_REWARD = {"success_bonus": 1000.0, "hit_penalty": True, "hit_weight": 10.0, "hit_radius": 0.25,
                "hit_lookahead": True, "anneal_lr": True}
_DEPLOY_SEARCH = {"path_filter": True, "train_path_filter": False, "path_cost": 10000.0, "path_escapes": 20}
OBSTACLE_PRESETS: Dict[str, Dict[str, Any]] = {
    "paper": {},
    # The default: the reward above on the paper's CNN, trained without the collision-aware
    # search and deployed with it (eval, render, play, export): trained with it, the policy
    # leans on the search and learns less. In the deployed search a path that hits costs more
    # than any feature distance (so a clear one always wins, and when every candidate hits the
    # latest hit wins; with inf the search would fall back to one blind to the obstacles), and
    # its shortlist holds the twenty escapes' nearest frames (stand, step back and aside, walk
    # and run all round; found once per database frame): most of the exact search's gain at
    # about the runtime budget (docs/obstacles.md, "The escape table").
    "mmrl": {**_MMRL_REWARD, **_DEPLOY_SEARCH},
    # The same with the cheap learner (a small CNN actor, an MLP critic, 8 minibatch steps per
    # rollout): 2.4x the training steps per second, less success per step (docs/obstacles.md).
    "mmrl-small": {**_MMRL_REWARD, **_DEPLOY_SEARCH, "network": "small-cnn", "num_minibatches": 4},
    # The default until the collision-aware search and the cheap learner (docs/obstacles.md's
    # nine-seed tables were measured with it): the paper's CNN, no path filter.
    "mmrl-cnn": dict(_MMRL_REWARD),
}


class ObstaclesVectorEnv(TargetVectorEnv):
    """N moving-obstacles characters stepped together in C++ (see the module docstring)."""

    core_type = _core.ObstacleVecEnv
    core_config_type = _core.ObstacleTaskConfig
    config_type = ObstaclesConfig
    layout = OBSTACLE_LAYOUT
    map_shape = OBSTACLE_MAP_SHAPE
    #: Finished episodes kept for pop_finished_episodes (a curriculum drains them every iteration).
    MAX_FINISHED_EPISODES = 100_000

    def __init__(self, num_envs: int = 64, *, render_mode: Optional[str] = None, **kwargs):
        if render_mode is not None:
            raise ValueError(f"render_mode: this env renders through mmrl render, got {render_mode!r}")
        super().__init__(num_envs, **kwargs)
        self.layout = self.observation_layout
        n = self.num_envs
        self._collision = np.zeros(n, np.uint8)
        self._hits = np.zeros(n, np.int32)
        # Curriculum bookkeeping: the stage label each env's episode runs with, the label of
        # the next resets, and (label, success) of episodes finished since the last drain.
        # Bounded: an env stepped without a curriculum draining it (evaluation, a viewer, an
        # RLlib rollout) grew these lists by every episode (bench/soak.py env: +177 MB/hour).
        self._stage_label = 0
        self._env_stage = np.zeros(n, np.int32)
        self._finished_stage: deque = deque(maxlen=self.MAX_FINISHED_EPISODES)
        self._finished_success: deque = deque(maxlen=self.MAX_FINISHED_EPISODES)

    def _observation_space(self) -> gym.spaces.Box:
        n_map = OBSTACLE_MAP_RANGE[1]
        rest = self.obs_dim - n_map
        low = np.concatenate([np.zeros(n_map, np.float32), np.full(rest, -np.inf, np.float32)])
        high = np.concatenate([np.ones(n_map, np.float32), np.full(rest, np.inf, np.float32)])
        return gym.spaces.Box(low, high, dtype=np.float32)

    def _task_step_buffers(self) -> tuple:
        return self._collision, self._hits

    def _task_infos(self, done: np.ndarray) -> Dict[str, np.ndarray]:
        self._finished_stage.extend(self._env_stage[done].tolist())
        self._finished_success.extend(self._success[done].astype(bool).tolist())
        return {"collision": self._collision.astype(bool),
                "episode_stage": np.where(done, self._env_stage, 0).astype(np.int32)}

    def _on_reset(self, which: Optional[np.ndarray]) -> None:
        self._env_stage[... if which is None else which] = self._stage_label

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
        """(stage labels, successes) of the episodes finished since the last call (at most the
        last MAX_FINISHED_EPISODES of them), as arrays."""
        stages = np.asarray(self._finished_stage, np.int32)
        success = np.asarray(self._finished_success, bool)
        self._finished_stage.clear()
        self._finished_success.clear()
        return stages, success

    # -- inspection (rendering, tests, evaluation) ---------------------------------------------
    @property
    def last_hits(self) -> np.ndarray:
        """hits(a_t) of every env's last action (0..3)."""
        return self._hits.copy()

    def obstacles(self, i: int) -> dict:
        """Env i's obstacles: centres (n,2), half_sizes (n,2), angles (n), velocities (n,2); world (x, z)."""
        return self._core.obstacles(int(i))

    def obstacles_after(self, i: int, frames: int) -> dict:
        """Env i's obstacles as they will be after ``frames`` played frames (the env's own motion rule)."""
        return self._core.obstacles_after(int(i), int(frames))

    def action_hits(self, i: int, action: np.ndarray):
        """For env i's current state: (hits, points (3, 2) world x/z, inside (3,) bool) of a
        12-d action's three future trajectory positions (the hit reward's count)."""
        a = np.ascontiguousarray(action, dtype=np.float32).reshape(-1)
        return self._core.action_hits(int(i), a)

    def path_hits(self, i: int, rows: np.ndarray) -> np.ndarray:
        """For env i's current state, the collision-aware search's test of each database row
        (valid frames): the frames ahead of its played path's first hit, 0 when clear (int32)."""
        return self._core.path_hits(int(i), np.ascontiguousarray(rows, np.int64).reshape(-1))

    def state_path_hits(self, i: int, features: np.ndarray) -> np.ndarray:
        """The same test of compressed controller states known by their normalized features
        (N, 27): each path is the quadratic through the start and the state's 10-, 20- and
        30-frame trajectory positions (int32 frames to the first hit, 0 when clear)."""
        return self._core.state_path_hits(int(i), features)

    def collides(self, i: int, x: float, z: float) -> bool:
        """Whether the body disc at world (x, z) overlaps one of env i's obstacles."""
        return bool(self._core.collides(int(i), float(x), float(z)))

    def sensor_map(self, i: int, previous: bool = False) -> np.ndarray:
        """Env i's current (or previous) sensor map, uint8 (16, 16) [row (forward)][col (left)]."""
        return self._core.sensor_map(int(i), previous)

    def sensor_positions(self, i: int) -> np.ndarray:
        """World (x, z) of env i's sensors, (16, 16, 2)."""
        return self._core.sensor_positions(int(i))


class ObstaclesEnv(SingleEnv):
    """A single moving-obstacles character (the same C++ core with one environment)."""

    vector_type = ObstaclesVectorEnv

    def _step_info(self) -> Dict[str, Any]:
        return {"hits": int(self._vec._hits[0])}

    def set_stage(self, max_speed: float, target_half_extent: float, label: int = 0) -> None:
        self._vec.set_stage(max_speed, target_half_extent, label)

    def obstacles(self) -> dict:
        return self._vec.obstacles(0)


def _callbacks(envs: ObstaclesVectorEnv, options: Mapping[str, Any]):
    return [Curriculum(envs, enabled=bool(options.get("curriculum", True)))]


def _set_stage(envs: ObstaclesVectorEnv, stage: int) -> None:
    envs.set_stage(*stage_params(stage), label=stage)


def _training_config(config: ObstaclesConfig) -> ObstaclesConfig:
    return config if config.train_path_filter else config.replace(path_filter=False)


def _scene(env: ObstaclesVectorEnv):
    from .obstacles_scene import ObstacleScene

    return ObstacleScene(env)


TASK = Task(
    name="obstacles",
    summary="reach a target through 100 moving obstacles, 10-stage curriculum (paper, sections 4-5)",
    config_type=ObstaclesConfig,
    vector_env=ObstaclesVectorEnv,
    env=ObstaclesEnv,
    gym_id="mmrl/MovingObstacles-v0",
    # The binary sensor maps stay unnormalized. The CNN's update dominates the cost, so torch
    # gets both cores during updates (the env's threads idle then), and each rollout gets 2
    # epochs of 2 large minibatches (~160 us per env step on 2 cores).
    ppo_defaults={"obs_norm_exclude": OBSTACLE_MAP_RANGE, "torch_threads": 2, "update_epochs": 2,
                  "num_minibatches": 2, "learning_rate": 1e-3},
    presets=OBSTACLE_PRESETS,
    default_preset="mmrl",
    flags=(TaskFlag("--no-hit-reward", "hit_reward", False, "drop the hit reward (ablation)"),
           TaskFlag("--no-curriculum", "curriculum", False, "start at the hardest stage (ablation)",
                    target="callbacks")),
    callbacks=_callbacks,
    stages=10,
    set_stage=_set_stage,
    outcomes=("collision", "truncated"),
    scene=_scene,
    training_config=_training_config,
)
