"""The task registry: every target-reaching task is a plug-in declared by one :class:`Task`.

``get_task(name)`` is how commands, evaluation, rendering and export find a task; nothing
outside a task's own module branches on its name. Adding a task is a module that builds a
``Task`` (see docs/architecture.md) plus one ``register_task`` line, here for the built-in
ones or in your own code for yours.
"""
from __future__ import annotations

from typing import Dict, List

import gymnasium as gym

from .base import SingleEnv, TargetVectorEnv, Task, TaskConfig, TaskFlag, check_actions, make_config

_TASKS: Dict[str, Task] = {}


def register_task(task: Task, *, replace: bool = False) -> Task:
    """Make ``task`` known by name (and register its gymnasium id, if any)."""
    if not isinstance(task, Task):
        raise TypeError(f"register_task: expected an mmrl.tasks.Task, got {type(task).__name__}")
    if task.name in _TASKS and not replace and _TASKS[task.name] is not task:
        raise ValueError(f"register_task: a task named {task.name!r} is already registered")
    if task.default_preset is not None and task.default_preset not in task.presets:
        raise ValueError(f"register_task: default_preset {task.default_preset!r} of the {task.name} task is not one "
                         f"of its presets ({', '.join(task.presets) or 'none'})")
    _TASKS[task.name] = task
    if task.gym_id is not None and (replace or task.gym_id not in gym.registry):
        gym.register(id=task.gym_id, entry_point=task.env, vector_entry_point=task.vector_env)
    return task


def unregister_task(name: str) -> None:
    """Forget a task (its gymnasium id too); for tests and notebooks."""
    task = _TASKS.pop(name, None)
    if task is not None and task.gym_id is not None:
        gym.registry.pop(task.gym_id, None)


def get_task(name: str) -> Task:
    """The registered task called ``name``; ValueError listing the known ones otherwise."""
    try:
        return _TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; tasks are {', '.join(task_names())}") from None


def task_names() -> List[str]:
    return list(_TASKS)


from .plane import TASK as _PLANE  # noqa: E402
from .obstacles import TASK as _OBSTACLES  # noqa: E402
from .arrive import TASK as _ARRIVE  # noqa: E402

register_task(_PLANE)
register_task(_OBSTACLES)
register_task(_ARRIVE)

__all__ = ["Task", "TaskConfig", "TaskFlag", "TargetVectorEnv", "SingleEnv", "check_actions", "make_config",
           "register_task", "unregister_task", "get_task", "task_names"]
