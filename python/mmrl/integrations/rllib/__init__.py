"""Train the mmrl tasks with Ray RLlib's PPO, on one machine or a Ray cluster (extra
``mmrl[rllib]``; docs/cluster.md).

- :func:`register_envs` registers ``mmrl-plane``, ``mmrl-obstacles`` (every registered task)
  as RLlib env creators that return our C++-batched vector env in NEXT_STEP autoreset mode
  (use ``gym_env_vectorize_mode="vector_entry_point"``);
- :func:`share_database` puts a database in Ray's object store once; workers borrow it
  read-only, zero-copy (:class:`SharedDatabase` goes into ``env_config["db"]``);
- :class:`MMRLTorchModule` is our actor-critic as an RLModule;
- :class:`RLlibRun` is what ``mmrl train TASK --backend rllib`` runs: the same run directory
  as our trainer (config.json, metrics.csv, TensorBoard, latest.pt).
"""
try:
    import ray  # noqa: F401
    from ray.rllib.algorithms.ppo import PPOConfig  # noqa: F401
except ImportError as e:  # pragma: no cover - depends on the environment
    raise ImportError("mmrl.integrations.rllib needs Ray RLlib: pip install 'mmrl[rllib]' "
                      f"(importing it failed: {e})") from e

from .config import RLLIB_PRESETS, RLlibConfig
from .envs import SharedDatabase, make_env, process_memory, register_envs, share_database, worker_database
from .module import MMRLTorchModule
from .trainer import RLlibRun, WorkerLost, init_ray

__all__ = ["RLLIB_PRESETS", "RLlibConfig", "SharedDatabase", "make_env", "process_memory", "register_envs",
           "share_database", "worker_database", "MMRLTorchModule", "RLlibRun", "WorkerLost", "init_ray"]
