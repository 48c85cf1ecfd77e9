"""What the full path records of the moving-obstacles scene, for video, export and tests.

:class:`ObstacleScene` is the obstacles task's scene recorder (``Task.scene``), driven by
:class:`mmrl.rollout.FullPath`: before each step it reads the decision's sensor map, the
action's hit points and the obstacles as they will be on each of the step's frames (the
env's own motion rule, ``ObstacleVecEnv.obstacles_after``); after the step it keeps the
frames that were shown.
"""
from __future__ import annotations

from typing import Any, Dict, Optional

import numpy as np


def obstacle_corners(obst: Dict[str, np.ndarray], centres: Optional[np.ndarray] = None) -> np.ndarray:
    """(n, 4, 2) world (x, z) corners of the env's rectangles (``ObstaclesVectorEnv.obstacles``).

    A rectangle's frame is the world rotated by its angle about +Y (the yaw convention): a
    local point (u, v) is at world ``centre + (c u + s v, -s u + c v)``.
    """
    c = np.asarray(obst["centres"] if centres is None else centres, np.float64)
    h = np.asarray(obst["half_sizes"], np.float64)
    a = np.asarray(obst["angles"], np.float64)
    cos, sin = np.cos(a)[:, None], np.sin(a)[:, None]
    u = np.array([-1.0, 1.0, 1.0, -1.0])[None] * h[:, :1]
    v = np.array([-1.0, -1.0, 1.0, 1.0])[None] * h[:, 1:]
    return np.stack([c[:, :1] + cos * u + sin * v, c[:, 1:] - sin * u + cos * v], axis=-1)


class ObstacleScene:
    """Scene recorder of env 0 of a 1-env ``ObstaclesVectorEnv``."""

    def __init__(self, env):
        self.env = env
        self._frames: list = []

    def start_frame(self) -> Dict[str, np.ndarray]:
        """Per-frame values of an episode's reset pose."""
        return {"obstacles": obstacle_corners(self.env.obstacles(0))[None]}

    def before_step(self, action: np.ndarray) -> Dict[str, Any]:
        env = self.env
        obstacles = env.obstacles(0)
        hits, points, inside = env.action_hits(0, action)
        # The obstacles on each frame the step may show (static ones do not move).
        self._frames = [obstacle_corners(obstacles, env.obstacles_after(0, k)["centres"])
                        for k in range(1, env.config.frames_per_step + 1)]
        sensor_map, sensor_positions = env.sensor_map(0), env.sensor_positions(0)
        return {"obstacles": obstacles, "sensor_map": sensor_map, "sensor_positions": sensor_positions,
                "hits": int(hits), "hit_points": np.asarray(points), "hit_inside": np.asarray(inside, bool),
                "scene_step": {"hit_inside": np.asarray(inside, bool), "sensor_maps": sensor_map,
                               "sensor_positions": np.asarray(sensor_positions, np.float32)}}

    def sensors(self) -> Dict[str, np.ndarray]:
        """The sensor map of the next decision and where its cells are (world)."""
        return {"positions": self.env.sensor_positions(0), "map": self.env.sensor_map(0)}

    def after_step(self, shown: int) -> Dict[str, Any]:
        return {"scene_frames": {"obstacles": np.array(self._frames[:shown], np.float32)}}
