"""A training run directory: the one reader and writer of ``config.json``.

A run directory written by ``mmrl train`` holds::

    config.json          {"task": NAME, "data": DATA SPEC, "num_envs": N,
                          "task_config": {...}, "ppo": {...},
                          "skeleton": {"joint_names": [...], "parents": [...]}}
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
from .motion.sources import database_from_spec
from .tasks import Task, get_task

CONFIG_NAME = "config.json"
CHECKPOINT_NAME = "latest.pt"


class RunDir:
    """A run directory (see the module docstring). ``RunDir(path)`` reads an existing one."""

    def __init__(self, path: "str | os.PathLike[str]", require_run: bool = False):
        self.path = Path(path)
        if not self.path.is_dir():
            raise not_a_run(self.path, "no such run directory" if not self.path.exists() else "a file, not a folder")
        self.config: Dict[str, Any] = self._read_config()
        if require_run and not (self.path / CONFIG_NAME).is_file():
            raise not_a_run(self.path, f"no {CONFIG_NAME} in it")
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
               database=None, backend: str = "ppo") -> "RunDir":
        """Make ``path`` (if needed) and write its config.json atomically (``callback_options``:
        the task switches its callbacks read, e.g. ``{"curriculum": False}``). ``database``: the
        run's Database, whose skeleton config.json records; when ``path`` already records
        another skeleton (a resumed run whose data changed), InputError and nothing is written.
        ``backend`` "rllib": ``ppo_config`` is an ``RLlibConfig``, recorded under "rllib"."""
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        config = {"task": task.name, "data": with_run_relative_paths(data, path), "num_envs": int(num_envs),
                  "task_config": asdict(task_config)}
        if backend == "rllib":
            config.update(backend="rllib", rllib=asdict(ppo_config))
        else:
            config["ppo"] = asdict(ppo_config)
        if callback_options:
            config["callback_options"] = dict(callback_options)
        if database is not None:
            if (path / CONFIG_NAME).is_file():
                cls(path).check_database(database, f"the data of {path}")
            config["skeleton"] = skeleton_of(database)
        write_config(path, config)
        return cls(path)

    def check_database(self, db, source: str) -> None:
        """InputError unless ``db`` has the skeleton the run was trained on (runs written before
        config.json recorded it pass): a policy drives only the skeleton of its own database."""
        saved = self.config.get("skeleton")
        if saved is None or skeleton_of(db) == saved:
            return
        names = saved.get("joint_names", [])
        raise InputError(f"{source}: its skeleton ({db.num_joints} joints: {_first(db.joint_names)}) is not the one "
                         f"the run {self.path} was trained on ({len(names)} joints: {_first(names)}); a run's policy "
                         f"only drives the skeleton of its own database")

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
        try:
            return task.config_from_dict(self.config.get("task_config") or {})
        except ValueError as e:
            raise InputError(f"{self.path}/{CONFIG_NAME}: {e}") from None

    @property
    def data_spec(self) -> Dict[str, Any]:
        """The run's data spec, its paths found again if the run or its data moved: a path
        recorded relative to the run first, then the absolute one, then a file of the same name
        beside the run or in it. InputError naming the missing file and ``--db`` otherwise."""
        spec = self.config.get("data")
        if spec is None:
            return {"synthetic": True}
        if not isinstance(spec, dict):
            return spec
        spec = dict(spec)
        relative = spec.pop("from_run", {}) or {}
        if spec.get("db"):
            spec["db"] = self._find(spec["db"], relative.get("db"), "database", "--db FILE")
        if spec.get("data"):
            rel = list(relative.get("data") or [])
            spec["data"] = [self._find(p, rel[k] if k < len(rel) else None, "data", "--data DIR")
                            for k, p in enumerate(spec["data"])]
        return spec

    def _find(self, recorded: str, relative: Optional[str], what: str, flag: str) -> str:
        name = Path(recorded).name
        candidates = ([self.path / relative] if relative else []) + [Path(recorded), self.path.parent / name,
                                                                     self.path / name]
        for c in candidates:
            if c.exists():
                return str(c.resolve())
        raise InputError(f"{self.path}: its {what} {recorded} is missing (moved or deleted?); pass it with {flag}")

    def database(self):
        """The run's database (built or loaded once)."""
        if self._db is None:
            spec = self.data_spec
            db = database_from_spec(spec)
            self.check_database(db, f"the data of {self.path} ({spec})")
            self._db = db
        return self._db

    @property
    def checkpoint(self) -> Path:
        return self.path / CHECKPOINT_NAME

    def policy(self, device: str = "cpu"):
        """The run's trained policy (``latest.pt``)."""
        from .rl.ppo import CheckpointError, load_policy

        if not self.checkpoint.is_file():
            raise not_a_run(self.path, f"no {CHECKPOINT_NAME} in it: it stopped before its first checkpoint"
                            if self.config else f"no {CONFIG_NAME} or {CHECKPOINT_NAME} in it")
        try:
            return load_policy(self.checkpoint, device=device)
        except CheckpointError as e:
            snapshots = sorted(self.path.glob("snapshot_*.pt"), key=lambda p: p.stat().st_mtime)
            hint = (f"; its newest snapshot {snapshots[-1].name} may still be good: copy it over {CHECKPOINT_NAME}"
                    if snapshots else "; train again, or restore latest.pt from a copy")
            raise CheckpointError(str(e).splitlines()[0][:300] + hint) from None


def not_a_run(path: Path, why: str) -> InputError:
    """The one wording of "this is not a run": ``PATH: not a training run (WHY; ...)``."""
    return InputError(f"{path}: not a training run ({why}; runs are made by mmrl train)")


def with_run_relative_paths(spec: Any, run: Path) -> Any:
    """A data spec that also records its paths relative to the run directory ("from_run"), so
    a run moved together with its data still finds it."""
    if not isinstance(spec, dict) or not (spec.get("db") or spec.get("data")):
        return spec

    def rel(p: str) -> Optional[str]:
        try:
            return os.path.relpath(p, Path(run).resolve())
        except ValueError:  # another drive
            return None

    out = {k: v for k, v in spec.items() if k != "from_run"}
    out["from_run"] = {"db": rel(spec["db"])} if spec.get("db") else {"data": [rel(p) for p in spec["data"]]}
    return out


def write_config(path: Path, config: Dict[str, Any]) -> None:
    atomic_write_text(Path(path) / CONFIG_NAME, json.dumps(config, indent=2, default=list) + "\n")


def skeleton_of(db) -> Dict[str, Any]:
    """What config.json records of a run database's skeleton: joint names and parents."""
    return {"joint_names": list(db.joint_names), "parents": [int(p) for p in db.parents]}


def _first(names, count: int = 4) -> str:
    return ", ".join(list(names)[:count]) + (", ..." if len(names) > count else "")
