"""The plane task, ``mmrl/Plane-v0`` (paper, section 3).

The policy writes the 12-d trajectory half of a motion-matching query every 6 frames (0.2 s)
and must bring the character within 0.5 m of a random target.

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
in one C++ call (``_core.PlaneVecEnv``, cpp/include/mmrl/tasks/plane.hpp) with the GIL
released; see :mod:`mmrl.tasks.base` for the autoreset and infos contract.
"""
from __future__ import annotations

from .. import _core
from .drawing import drawing
from .base import SingleEnv, TargetVectorEnv, Task, TaskConfig
from .options import task_options


@task_options(_core.PlaneTaskConfig)
class PlaneConfig(TaskConfig):
    """Numbers of the plane task (all configurable): exactly the shared ones of
    :class:`~mmrl.tasks.base.TaskConfig`, with its defaults."""

    task_label = "plane-task"


class PlaneVectorEnv(TargetVectorEnv):
    """N plane-task characters stepped together in C++ (see the module docstring)."""

    metadata = dict(TargetVectorEnv.metadata, render_modes=["rgb_array"])
    core_type = _core.PlaneVecEnv
    core_config_type = _core.PlaneTaskConfig
    config_type = PlaneConfig

    def render(self):
        return drawing("topdown")([self.env_state(i) for i in range(self.num_envs)])


class PlaneEnv(SingleEnv):
    """A single plane-task character (the same C++ core with one environment)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}
    vector_type = PlaneVectorEnv

    def render(self):
        return drawing("state")(self.db, self._vec.env_state(0))


#: ``mmrl train plane --preset NAME``. "paper" is the task as written. "quality" (what ``mmrl
#: train plane`` uses unless told otherwise) keeps the motion clean (docs/quality.md): a
#: transition cost of 60 (a jump to another clip
#: must beat the current clip's continuation by that squared normalized distance) and a
#: discount of 0.97, which buys back the speed the bias costs. On all shared data after 1M
#: steps (3 seeds): 2.51-2.54 s to target, foot sliding 26-27 cm/s with IK off and 1.6
#: transitions/s, where the paper's rule gives 2.49 s, 55 cm/s and 4.7/s.
#: "smooth" adds a reward cost for what each jump asks the blend to hide (the pose-feature distance
#: between the continuation and the matched frame, weight 10): smoother feet after a short
#: training (20 s, 3 seeds: foot sliding 14.9-18.3 cm/s with IK off, below the walking joystick's
#: 19.7) at the price of speed (4.6-5.3 s to target after 20 s, 3.3 s after 1M steps).
PLANE_PRESETS = {
    "paper": {},
    "quality": {"transition_cost": 60.0, "gamma": 0.97},
    "smooth": {"transition_cost": 60.0, "gamma": 0.97, "transition_pose_weight": 10.0},
}

TASK = Task(
    name="plane",
    summary="reach a random target on an empty plane (paper, section 3)",
    config_type=PlaneConfig,
    vector_env=PlaneVectorEnv,
    env=PlaneEnv,
    gym_id="mmrl/Plane-v0",
    # Snapshots for the paper's Figure 4 (trajectories at about 20k, 100k, 533k and 1M steps).
    ppo_defaults={"snapshot_steps": (20_000, 100_000, 533_000, 1_000_000)},
    # One policy for many requests moves too far per update at the default rate once its std
    # has shrunk (docs/styles.md: KL 0.56 against a specialist's 0.22, and 1.08-1.70x the
    # specialists' time); stopping an update's epochs past KL 0.05 closes the gap.
    request_ppo_defaults={"target_kl": 0.05},
    presets=PLANE_PRESETS,
    default_preset="quality",
)
