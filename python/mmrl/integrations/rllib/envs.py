"""The mmrl tasks as RLlib environments: one C++-batched vector env per RLlib EnvRunner, over
a database every worker borrows from Ray's object store.

- ``register_envs()`` registers ``mmrl-<task>`` for every task with ``ray.tune``. RLlib's
  ``gym_env_vectorize_mode="vector_entry_point"`` then calls the creator once per EnvRunner
  with ``num_envs``; the creator returns the task's own ``TargetVectorEnv`` (N characters in
  one C++ call), never N single envs behind Python wrappers.
- ``share_database(db)`` puts the database's arrays into the object store once and returns
  a small picklable handle for ``env_config``. On a worker, ``ray.get`` maps the arrays
  read-only from shared memory and ``Database.from_shared_arrays`` borrows them: no worker
  holds a copy of the motion data (``bench/bench_rllib.py`` measures each worker's memory).
  Only the search index (a few MB per 100k frames) is built per worker.
- The env runs in gymnasium's NEXT_STEP autoreset mode, which RLlib's EnvRunner expects
  (tests/test_autoreset.py: the same episodes as our trainer's SAME_STEP mode).
- ``EpisodeLog`` keeps, per worker, the episodes that finished (return, length, success, the
  curriculum stage they ran with) and the decisions' match statistics, which the trainer
  drains after every iteration for ``metrics.csv`` and the curriculum.
"""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from typing import Any, Dict, List, Optional

import numpy as np
from gymnasium.vector import AutoresetMode, VectorWrapper

ENV_PREFIX = "mmrl-"


@dataclass(frozen=True)
class SharedDatabase:
    """A database in Ray's object store: what ``env_config`` carries instead of the arrays.
    ``ref`` is the ObjectRef of ``Database.shared_arrays()``; ``nbytes`` their total size."""

    ref: Any
    nbytes: int


def share_database(db) -> SharedDatabase:
    """``ray.put`` the database's arrays once (the driver keeps the handle for the run)."""
    import ray

    arrays = db.shared_arrays()
    arrays = {k: (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v) for k, v in arrays.items()}
    nbytes = sum(v.nbytes for v in arrays.values() if isinstance(v, np.ndarray))
    return SharedDatabase(ray.put(arrays), int(nbytes))


# Per worker process: the database borrowed from the object store, by ObjectRef, so several
# envs of one process share it too.
_WORKER_DATABASES: Dict[str, Any] = {}
_WORKER_ENVS: List["EpisodeLog"] = []


def worker_database(shared: SharedDatabase):
    """The database behind ``shared``, borrowed from the object store (once per process)."""
    import ray

    from ...motion.database import Database

    key = shared.ref.hex()
    if key not in _WORKER_DATABASES:
        _WORKER_DATABASES[key] = Database.from_shared_arrays(ray.get(shared.ref))
    return _WORKER_DATABASES[key]


class EpisodeLog(VectorWrapper):
    """Records the finished episodes and the decisions' statistics of a vector env, and
    optionally scales its rewards (``reward_scale``; the logged returns stay unscaled).
    ``task``: the env's task (its ``stages`` say whether a curriculum stage applies)."""

    def __init__(self, env, task, reward_scale: float = 1.0):
        super().__init__(env)
        self.task = task
        self.reward_scale = float(reward_scale)
        self._returns: List[float] = []
        self._lengths: List[int] = []
        self._success: List[bool] = []
        self._stages: List[int] = []
        _WORKER_ENVS.append(self)

    def step(self, actions):
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        done = infos.get("_episode_return")
        if done is not None and done.any():
            self._returns.extend(infos["episode_return"][done].tolist())
            self._lengths.extend(infos["episode_length"][done].tolist())
            self._success.extend(infos["success"][done].tolist())
            stages = infos.get("episode_stage")
            self._stages.extend(stages[done].tolist() if stages is not None else [0] * int(done.sum()))
        if self.reward_scale != 1.0:
            rewards = rewards * np.float32(self.reward_scale)
        return obs, rewards, terminated, truncated, infos

    def drain(self) -> Dict[str, Any]:
        """The episodes and match statistics since the last drain (then forgets them)."""
        out = {"returns": self._returns, "lengths": self._lengths, "success": self._success,
               "stages": self._stages, "match": self.env.unwrapped.pop_match_stats()}
        self._returns, self._lengths, self._success, self._stages = [], [], [], []
        return out


def drain_worker(_runner=None) -> List[Dict[str, Any]]:
    """Every EpisodeLog of this process, drained (the trainer calls it on each EnvRunner)."""
    return [log.drain() for log in _WORKER_ENVS]


def _apply_stage(params, label: int, _runner=None) -> int:
    for log in _WORKER_ENVS:
        if log.task.stages:  # a process may hold envs of an earlier trainer's task without stages
            log.env.unwrapped.set_stage(*params, label=label)
    return len(_WORKER_ENVS)


def set_worker_stage(params, label: int):
    """A function for ``foreach_env_runner`` that puts every env of the worker process at
    curriculum stage ``label`` for its next resets. A partial of a module-level function:
    Ray pickles it by reference, so it reaches the worker's own envs (a closure would be
    pickled by value, with a copy of this process's env list)."""
    return functools.partial(_apply_stage, tuple(params), int(label))


def worker_report(shared: SharedDatabase, _runner=None) -> Dict[str, Any]:
    """This worker's memory (:func:`process_memory`) and which database arrays it borrows."""
    return {"memory": process_memory(), "borrowed": worker_database(shared).borrowed_arrays}


def make_env(config) -> EpisodeLog:
    """The RLlib env creator: ``config`` (RLlib's EnvContext) holds ``task``, ``db``
    (a :class:`SharedDatabase`), ``task_config`` (dict), ``num_envs`` (RLlib adds it),
    ``threads`` (C++ threads per worker, default 1) and ``reward_scale``."""
    from ...tasks import get_task

    task = get_task(config["task"])
    db = worker_database(config["db"])
    threads = int(config.get("threads", 1))
    torch_threads = config.get("torch_threads", 1)
    if torch_threads:
        import torch

        torch.set_num_threads(int(torch_threads))
    task_config = task.config_from_dict(config.get("task_config", {}), strict=True)
    # The training envs (a task may train with other options than it evaluates with).
    env = task.make_vector_env(int(config.get("num_envs", 1)), db=db, config=task.train_config(task_config),
                               num_threads=threads,
                               autoreset_mode=AutoresetMode.NEXT_STEP)
    return EpisodeLog(env, task, reward_scale=float(config.get("reward_scale", 1.0)))


def register_envs() -> List[str]:
    """Register ``mmrl-<task>`` with ``ray.tune`` for every registered task; returns the names."""
    from ray.tune.registry import register_env

    from ...tasks import task_names

    names = []
    for name in task_names():
        register_env(ENV_PREFIX + name, make_env)
        names.append(ENV_PREFIX + name)
    return names


def process_memory(pid: Optional[int] = None) -> Dict[str, float]:
    """RSS, USS (private memory) and shared memory of a process in MB (Linux smaps_rollup):
    pages mapped from the object store count in RSS and in ``shared``, not in ``uss``."""
    path = f"/proc/{pid or os.getpid()}/smaps_rollup"
    fields: Dict[str, float] = {}
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 2 and parts[0].endswith(":") and parts[1].isdigit():
                fields[parts[0][:-1]] = int(parts[1]) / 1024.0
    uss = fields.get("Private_Clean", 0.0) + fields.get("Private_Dirty", 0.0)
    return {"rss_mb": fields.get("Rss", 0.0), "uss_mb": uss, "pss_mb": fields.get("Pss", 0.0),
            "shared_mb": fields.get("Shared_Clean", 0.0) + fields.get("Shared_Dirty", 0.0)}
