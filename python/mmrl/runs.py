"""A training run directory: the one reader and writer of ``config.json``.

A run directory written by ``mmrl train`` holds::

    config.json          {"task": NAME, "data": DATA SPEC, "num_envs": N,
                          "task_config": {...}, "ppo": {...}}
    latest.pt            the newest checkpoint (atomic), snapshot_<step>.pt
    metrics.csv          one row per PPO iteration (and TensorBoard event files)

:class:`RunDir` loads the task, its config, the database and the policy of a run, so every
command reads a run the same way.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Dict, Optional

from .errors import InputError
from .io import atomic_write_text
from .sources import database_from_spec
from .tasks import Task, get_task

CONFIG_NAME = "config.json"
CHECKPOINT_NAME = "latest.pt"


class RunDir:
    """A run directory (see the module docstring). ``RunDir(path)`` reads an existing one."""

    def __init__(self, path: "str | os.PathLike[str]"):
        self.path = Path(path)
        if not self.path.is_dir():
            raise InputError(f"{self.path}: no such run directory")
        self.config: Dict[str, Any] = self._read_config()
        self._db = None

    def _read_config(self) -> Dict[str, Any]:
        path = self.path / CONFIG_NAME
        if not path.is_file():
            return {}
        try:
            cfg = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise InputError(f"{path}: not valid JSON ({e})") from e
        if not isinstance(cfg, dict):
            raise InputError(f"{path}: expected a JSON object")
        return cfg

    @classmethod
    def create(cls, path: "str | os.PathLike[str]", *, task: Task, data: Dict[str, Any], num_envs: int,
               task_config, ppo_config, callback_options: Optional[Dict[str, Any]] = None,
               backend: str = "ppo") -> "RunDir":
        """Make ``path`` (if needed) and write its config.json atomically (``callback_options``:
        the task switches its callbacks read, e.g. ``{"curriculum": False}``). ``backend``
        "rllib": ``ppo_config`` is an ``RLlibConfig``, recorded under "rllib"."""
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        config = {"task": task.name, "data": data, "num_envs": int(num_envs), "task_config": asdict(task_config)}
        if backend == "rllib":
            config.update(backend="rllib", rllib=asdict(ppo_config))
        else:
            config["ppo"] = asdict(ppo_config)
        if callback_options:
            config["callback_options"] = dict(callback_options)
        write_config(path, config)
        return cls(path)

    # -- what the run holds --------------------------------------------------------------------
    @property
    def task_name(self) -> Optional[str]:
        return self.config.get("task")

    @property
    def task(self) -> Optional[Task]:
        """The run's task (None for a directory without config.json)."""
        name = self.task_name
        if name is None:
            return None
        try:
            return get_task(name)
        except ValueError as e:
            raise InputError(f"{self.path}: {e} in {CONFIG_NAME}") from None

    def task_config(self, task: Optional[Task] = None):
        """The run's own task numbers, or the defaults of ``task`` when the run is of another task."""
        task = task or self.task
        if task is None:
            raise InputError(f"{self.path}: no {CONFIG_NAME}, so no task")
        if self.task_name not in (None, task.name):
            return task.default_config()
        return task.config_from_dict(self.config.get("task_config") or {})

    @property
    def data_spec(self) -> Dict[str, Any]:
        spec = self.config.get("data")
        return spec if spec is not None else {"synthetic": True}

    def database(self):
        """The run's database (built or loaded once)."""
        if self._db is None:
            self._db = database_from_spec(self.data_spec)
        return self._db

    @property
    def checkpoint(self) -> Path:
        return self.path / CHECKPOINT_NAME

    def policy(self, device: str = "cpu"):
        """The run's trained policy (``latest.pt``)."""
        from .ppo import load_policy

        if not self.checkpoint.is_file():
            raise InputError(f"{self.checkpoint}: no trained policy in this run directory")
        return load_policy(self.checkpoint, device=device)



def write_config(path: Path, config: Dict[str, Any]) -> None:
    atomic_write_text(Path(path) / CONFIG_NAME, json.dumps(config, indent=2, default=list) + "\n")
