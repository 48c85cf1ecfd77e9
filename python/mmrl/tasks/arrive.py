"""The arrive task, ``mmrl/Arrive-v0`` (issue 38, docs/arrive.md): reach a target position *and*
a facing, and come to rest there, as a game character walks to a spot and faces the door.

- observation: ``[c_t (15), g_t (2), f_t (2)]``: the plane task's pose features and target, and
  the target facing in the character frame as ``(sin, cos)`` of its yaw there;
- action: the plane task's (12 normalized trajectory features, clipped to the action box);
- reward: ``exp(-|g_t|) + facing_weight * exp(-|g_t| / success_radius) * (1 + cos e) / 2``
  per step (``e`` the facing error) plus ``success_bonus`` on success;
- success (terminates): ``hold_time`` seconds of consecutive frames within ``success_radius``
  (0.15 m) of the target, within ``facing_tolerance`` (0.2618 rad = 15 degrees) of its facing,
  and slower than ``stop_speed`` (0.15 m/s). ``max_steps`` (150 = 30 s) truncates.

Angles are radians at every interface (a facing is a world yaw about +Y: forward is
``(sin yaw, cos yaw)``). Data that never stops cannot succeed here (docs/arrive.md).

The vector env steps all N characters in one C++ call (``_core.ArriveVecEnv``,
cpp/include/mmrl/tasks/arrive.hpp) with the GIL released.
"""
from __future__ import annotations

import numpy as np

from .. import _core
from ..motion.kinds import check_can_stop
from .base import Task, TaskConfig
from .layout import obs_segment
from .options import task_options
from .plane import PlaneEnv, PlaneVectorEnv


@task_options(_core.ArriveTaskConfig)
class ArriveConfig(TaskConfig):
    """Numbers of the arrive task: the shared ones of :class:`~mmrl.tasks.base.TaskConfig`
    (``success_radius`` 0.15 m, ``max_steps`` 150 here) and the tolerances of a rest."""

    task_label = "arrive-task"


class ArriveVectorEnv(PlaneVectorEnv):
    """N arrive-task characters stepped together in C++ (see the module docstring); drawn as the
    plane task's."""

    core_type = _core.ArriveVecEnv
    core_config_type = _core.ArriveTaskConfig
    config_type = ArriveConfig

    def set_facing(self, i: int, yaw: float) -> np.ndarray:
        """Set env i's target facing (world yaw, radians); returns its new observation."""
        self._core.set_facing(int(i), float(yaw))
        return self.observe(i)


class ArriveEnv(PlaneEnv):
    """A single arrive-task character (the same C++ core with one environment)."""

    vector_type = ArriveVectorEnv


def final_errors(layout, final_obs: np.ndarray) -> dict:
    """The position error (cm) and the facing error (degrees) where an episode ended."""
    goal, facing = final_obs[obs_segment(layout, "goal")], final_obs[obs_segment(layout, "facing")]
    return {"final_position_error_cm": float(100 * np.hypot(goal[0], goal[1])),
            "final_facing_error_deg": float(np.degrees(abs(np.arctan2(facing[0], facing[1]))))}


TASK = Task(
    name="arrive",
    summary="reach a target and stop there facing a given direction (issue 38)",
    config_type=ArriveConfig,
    vector_env=ArriveVectorEnv,
    env=ArriveEnv,
    gym_id="mmrl/Arrive-v0",
    presets={"paper": {}, "quality": {"transition_cost": 60.0, "gamma": 0.97}},
    default_preset="quality",
    check_data=check_can_stop,
    final_values=final_errors,
    rests=True,
)
