"""Scripted policies with the same interface as trained ones: ``act(obs[N, D]) -> actions[N, 12]``.

Observations are a task's (its ``observation_layout`` names the segments; the joystick reads the
"goal", the target (x, z) in the character frame, meters, and the arrive task's "facing").
Actions are the 12-d trajectory features in the database's normalized units.
"""
from __future__ import annotations

import warnings
from typing import Optional, Tuple

import numpy as np

from .. import _core
from ..motion.database import POSE_DIM, TRAJECTORY_DIM, Database
from ..tasks.layout import obs_segment

#: Observation sizes an unbound joystick told apart (deprecated: bind it to the env's layout).
_OBSTACLE_GOAL = sum(size for name, size in _core.ObstacleVecEnv.layout if name != "goal")
OBSERVATION_DIMS = (POSE_DIM + 2, _OBSTACLE_GOAL + 2)


def goal_offset(obs_dim: int) -> int:
    """Deprecated (goes in the next release): where g_t starts in a plane or obstacles
    observation of ``obs_dim`` floats, told by its length. Read the env's
    ``observation_layout`` instead (:func:`mmrl.tasks.layout.obs_segment`)."""
    warnings.warn("goal_offset is deprecated: read the goal from the env's observation_layout "
                  "(mmrl.tasks.layout.obs_segment(layout, 'goal'))", DeprecationWarning, stacklevel=2)
    return _goal_by_length(obs_dim)


def _goal_by_length(obs_dim: int) -> int:
    return _OBSTACLE_GOAL if int(obs_dim) >= _OBSTACLE_GOAL + 2 else POSE_DIM


#: Frames ahead of the three trajectory samples (+10, +20, +30), from the C++ feature layout.
TRAJECTORY_FRAMES = tuple(_core.TRAJECTORY_OFFSETS)
_LAST_POSITION = _core.TRAJECTORY_POSITION_COLUMNS[2]  # x of the +30-frame position (z next)


def frame_speeds(db: Database) -> np.ndarray:
    """Each valid frame's speed (m/s): the distance to its +30-frame trajectory sample over that time."""
    f = db.features[db.valid_mask]
    return np.hypot(f[:, _LAST_POSITION], f[:, _LAST_POSITION + 1]) * db.fps / TRAJECTORY_FRAMES[2]


#: Frames slower than this (m/s) stand, turn in place or shuffle: neither walking nor running.
MOVING_SPEED = 0.5
#: The walk-to-run boundary (m/s): people switch gaits at about 2 m/s.
RUN_SPEED = 2.0


def database_speeds(db: Database) -> Tuple[float, float]:
    """(walk, run) speeds of a database, m/s.

    The speed of a valid frame is the distance to its +30-frame trajectory sample over that
    time. Frames under :data:`MOVING_SPEED` are left out (idles, turns in place, side steps);
    the walking speed is the median of the rest under :data:`RUN_SPEED`, the running speed the
    median of those at or over it. Bandai-Namco: 1.15 and 2.76 m/s; LAFAN1: 0.93 and 2.51; the
    synthetic default (walks at 1.3, runs at 3.0): 1.26 and 2.91. Data that never runs gets its
    90th-percentile speed as the running speed, data that never walks its 10th percentile as
    the walking one.
    """
    speed = frame_speeds(db)
    moving = speed[speed >= MOVING_SPEED]
    if moving.size == 0:
        raise ValueError(f"the database has no frame moving {MOVING_SPEED} m/s or faster: it has no walking "
                         "speed (a joystick needs one: give its speed)")
    walking, running = moving[moving < RUN_SPEED], moving[moving >= RUN_SPEED]
    walk = float(np.median(walking)) if walking.size else float(np.percentile(moving, 10))
    run = float(np.median(running)) if running.size else float(np.percentile(moving, 90))
    return walk, max(walk, run)


class JoystickPolicy:
    """A straight line toward the target at a fixed speed, facing it: a gamepad held toward the target.

    It reads only the target (the observation's last two floats), so on the moving-obstacles
    task it ignores the obstacles: the baseline of the paper's comparison.

    Args:
        db: the database whose normalization the actions use.
        speed: m/s; default: the database's walking speed (:func:`database_speeds`).
        arrive: never ask to go past the target: each trajectory position is at most the
            target's distance away (a player easing the stick at the target). Off for the
            ``joystick`` baselines (as measured in the docs); on for the equal-speed line
            (:mod:`mmrl.eval.reference`), whose fast joysticks would otherwise circle the target.
            On a task whose observation has a "facing" segment (the arrive task), the
            trajectory's directions turn to that facing from the sample that reaches the target
            on: the arrive joystick (docs/arrive.md), which slows down and turns at the end.
    """

    def __init__(self, db: Database, speed: Optional[float] = None, arrive: bool = False, layout=None):
        self.arrive = bool(arrive)
        if speed is None:
            speed = database_speeds(db)[0]
        if not np.isfinite(speed) or speed <= 0:
            raise ValueError(f"speed must be positive, got {speed!r}")
        self.speed = float(speed)
        self._mean = np.asarray(db.feature_mean[POSE_DIM:], np.float32)
        self._scale = np.asarray(db.feature_scale[POSE_DIM:], np.float32)
        self._times = np.array(TRAJECTORY_FRAMES, np.float32) / db.fps
        self._goal: Optional[int] = None  # where g_t starts, from bind_layout
        self._facing: Optional[int] = None  # where the target facing starts, if the layout has one
        if layout is not None:
            self.bind_layout(layout)

    def bind_layout(self, layout) -> "JoystickPolicy":
        """Read g_t where the env's ``observation_layout`` ((name, size), ...) puts the "goal"
        segment (the episode loops call it through ``policy_actions``; ``layout=`` at construction
        does the same). Returns self."""
        try:
            self._goal = obs_segment(layout, "goal").start
        except KeyError as e:
            raise ValueError(f"layout: the joystick reads the goal, but {e.args[0]}") from None
        names = [name for name, _ in layout]
        self._facing = obs_segment(layout, "facing").start if "facing" in names else None
        return self

    @classmethod
    def preset(cls, db: Database, name: str) -> "JoystickPolicy":
        """``"joystick"`` (walking speed) or ``"joystick-run"`` (running speed)."""
        walk, run = database_speeds(db)
        if name == "joystick":
            return cls(db, walk)
        if name == "joystick-run":
            return cls(db, run)
        raise ValueError(f"unknown joystick preset {name!r}; presets are 'joystick' and 'joystick-run'")

    def raw_trajectory(self, obs: np.ndarray) -> np.ndarray:
        """(N, 12) trajectory in meters / unit directions, character frame."""
        start = self._goal if self._goal is not None else self._unbound_goal(obs.shape[1])
        g = obs[:, start:start + 2].astype(np.float64)
        dist = np.linalg.norm(g, axis=1, keepdims=True)
        d = np.where(dist > 1e-6, g / np.maximum(dist, 1e-6), np.array([[0.0, 1.0]]))
        out = np.empty((obs.shape[0], TRAJECTORY_DIM), np.float32)
        facing = None if self._facing is None or not self.arrive else obs[:, self._facing:self._facing + 2]
        for k, t in enumerate(self._times):
            reach = np.minimum(self.speed * t, dist) if self.arrive else self.speed * t
            out[:, 4 * k:4 * k + 2] = d * reach
            # (sin, cos) of the facing's yaw in the character frame is its forward vector there
            out[:, 4 * k + 2:4 * k + 4] = d if facing is None else np.where(self.speed * t >= dist, facing, d)
        return out

    @staticmethod
    def _unbound_goal(obs_dim: int) -> int:
        """Deprecated (goes in the next release): where g_t starts in a plane or obstacles
        observation, told by its length."""
        warnings.warn("JoystickPolicy: reading the goal by the observation's length is deprecated; bind the "
                      "joystick to the env's layout (JoystickPolicy(db, layout=env.observation_layout), or "
                      "bind_layout)", DeprecationWarning, stacklevel=4)
        return _goal_by_length(obs_dim)

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions (N, 12) in the env's normalized units for observations (N, D) of the layout it
        is bound to (:meth:`bind_layout`)."""
        obs = np.asarray(obs)
        need = OBSERVATION_DIMS[0] if self._goal is None else self._goal + 2
        if self._facing is not None and self.arrive:
            need = max(need, self._facing + 2)
        if obs.ndim != 2 or obs.shape[1] < need:
            raise ValueError(f"obs: expected shape (N, D) with D >= {need} (where the layout's goal and facing end), "
                             f"got {obs.shape}")
        if not np.isfinite(obs).all():
            raise ValueError("obs: contains NaN or inf")
        return ((self.raw_trajectory(obs) - self._mean) / self._scale).astype(np.float32)

    __call__ = act
