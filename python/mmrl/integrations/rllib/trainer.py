"""``mmrl train TASK --backend rllib``: RLlib's PPO on the mmrl tasks, writing the same run
directory as our trainer.

The driver owns the run: it puts the database in Ray's object store once, builds RLlib's PPO
(our network as the RLModule, our C++ vector env on every EnvRunner), and after every RLlib
iteration drains the workers' finished episodes into ``metrics.csv``/TensorBoard rows with
our trainer's columns, advances the obstacles curriculum (the driver decides the stage from
all workers' episodes and sets it on every worker, restarted ones included), and when due
writes ``latest.pt``: the network, the observation statistics of RLlib's MeanStdFilter, the
action rescaling, the counters, the curriculum and RLlib's optimizer state, all as tensors
(a weights-only load reads it; ``mmrl eval``, ``render``, ``play`` and ``export`` load it
like any other). ``--resume`` rebuilds RLlib from config.json and loads latest.pt back.
"""
from __future__ import annotations

import dataclasses
import math
import os
import time
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np
import torch

from ...rl.checkpoints import load_checkpoint, save_checkpoint
from ...errors import InputError
from ...logs import MetricsLogger, ProgressBar
from ...metrics import rate_per_second
from ...rl.networks import network_name, task_policy_factory
from .config import RLlibConfig
from .envs import ENV_PREFIX, drain_worker, register_envs, set_worker_stage, share_database
from .module import MMRLTorchModule, range_mean_std_filter

LOG_2PI = math.log(2 * math.pi)


class WorkerLost(RuntimeError):
    """Workers died and RLlib could not restart them; the run directory stays resumable."""


# ----------------------------------------------------------------------------- ray
def init_ray(address: Optional[str], workers: int) -> Dict[str, float]:
    """Start a local Ray instance (``address`` None) or join a cluster. Refuses, with what to
    do, an address that does not answer or a cluster without a CPU for each worker."""
    import ray

    if ray.is_initialized():
        return ray.cluster_resources()
    kwargs: Dict[str, Any] = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
    if address:
        check_reachable(address)
        try:
            ray.init(address=address, **kwargs)
        except Exception as e:  # ConnectionError, or RuntimeError from the GCS client
            raise InputError(f"--address {address}: no Ray cluster answers there ({type(e).__name__}: "
                             f"{str(e).splitlines()[0] if str(e) else 'no reply'}); start one with "
                             f"`ray start --head` on the head node, or drop --address to train locally") from None
    else:
        ray.init(num_cpus=os.cpu_count() or 1, **kwargs)
    return ray.cluster_resources()


def check_reachable(address: str, timeout: float = 5.0) -> None:
    """A TCP connection to ``address``'s host:port, within ``timeout`` s, or InputError: Ray's own
    client waits minutes for an address where nothing answers."""
    import socket

    if address == "auto":
        return  # Ray finds the local cluster's address itself and fails at once without one
    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(f"--address {address}: expected HOST:PORT (e.g. 10.0.0.1:6379) or 'auto'")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as e:
        raise InputError(f"--address {address}: nothing answers there ({e.strerror or e}); start the head with "
                          f"`ray start --head --port {port}`, check the host and firewall, or drop --address "
                          f"to train on this machine") from None


def cpus_per_worker(resources: Dict[str, float], workers: int) -> float:
    """One CPU per worker when the cluster has them; on a smaller machine the workers share
    what there is (oversubscribed: more workers than cores), leaving half a core to the driver."""
    cpus = float(resources.get("CPU", 1.0))
    if workers <= 0:
        return 1.0
    return min(1.0, max(0.01, (cpus - 0.5) / workers))


# ----------------------------------------------------------------------------- the algorithm
def build_algorithm(task, db_handle, task_config, cfg: RLlibConfig, obs_dim: int, act_dim: int, model, cpus: float):
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    env_config = {"task": task.name, "db": db_handle, "task_config": dataclasses.asdict(task_config),
                  "threads": cfg.env_threads, "torch_threads": 1, "reward_scale": cfg.reward_scale}
    runners: Dict[str, Any] = dict(num_env_runners=cfg.workers, num_envs_per_env_runner=cfg.envs(),
                                   gym_env_vectorize_mode="vector_entry_point",
                                   rollout_fragment_length=cfg.rollout_fragment_length,
                                   num_cpus_per_env_runner=cpus)
    if cfg.obs_filter:
        runners["env_to_module_connector"] = range_mean_std_filter(
            tuple(cfg.obs_filter_exclude) if cfg.obs_filter_exclude is not None else None)
    use_gpu = cfg.device == "cuda" or (cfg.device == "auto" and torch.cuda.is_available())
    config = (
        PPOConfig()
        .environment(ENV_PREFIX + task.name, env_config=env_config, normalize_actions=cfg.normalize_actions,
                     clip_actions=False)
        .env_runners(**runners)
        .training(lr=[[0, cfg.lr], [cfg.total_steps, 0.0]] if cfg.anneal_lr else cfg.lr, gamma=cfg.gamma,
                  lambda_=cfg.lambda_, clip_param=cfg.clip_param,
                  train_batch_size_per_learner=cfg.batch_size(), minibatch_size=cfg.minibatch(),
                  num_epochs=cfg.num_epochs, vf_loss_coeff=cfg.vf_loss_coeff,
                  vf_clip_param=float("inf") if cfg.vf_clip_param is None else cfg.vf_clip_param,
                  entropy_coeff=cfg.entropy_coeff, use_kl_loss=cfg.use_kl_loss, kl_coeff=cfg.kl_coeff,
                  kl_target=cfg.kl_target, grad_clip=cfg.grad_clip)
        .rl_module(rl_module_spec=RLModuleSpec(module_class=MMRLTorchModule, model_config={
            "model_class": network_name(model), "model_kwargs": dict(getattr(model, "init_kwargs", {}))}))
        .learners(num_learners=0, num_gpus_per_learner=1 if use_gpu else 0)
        .fault_tolerance(restart_failed_env_runners=True, max_num_env_runner_restarts=cfg.max_worker_restarts)
        .debugging(seed=cfg.seed)
    )
    return config.build_algo()


def _learner(algo):
    return algo.learner_group._learner


def _net(algo) -> torch.nn.Module:
    return _learner(algo).module["default_policy"].net


def _filter_stats(algo) -> Optional[Dict[str, np.ndarray]]:
    """The merged MeanStdFilter statistics (mean, unbiased variance, count), or None."""
    pipeline = algo.env_runner._env_to_module
    for connector in pipeline.connectors:
        if "MeanStdFilter" in type(connector).__name__ and connector._filters is not None:
            rs = connector._filters[None].running_stats
            return {"mean": np.asarray(rs.mean, np.float64), "var": np.asarray(rs.var, np.float64),
                    "count": float(rs.n)}
    return None


def _set_filter_stats(algo, stats: Dict[str, np.ndarray]) -> None:
    """Every runner's MeanStdFilter (local and remote) continues from ``stats``."""
    mean, var, count = np.asarray(stats["mean"]), np.asarray(stats["var"]), int(stats["count"])

    def apply(runner):
        for connector in runner._env_to_module.connectors:
            if "MeanStdFilter" in type(connector).__name__:
                if connector._filters is None:
                    connector._init_new_filters()
                rs = connector._filters[None].running_stats
                rs.num_pushes = count
                rs.mean_array = mean.astype(rs.mean_array.dtype).copy()
                rs.sum_sq_diff_array = (var * max(count - 1, 0)).astype(rs.sum_sq_diff_array.dtype)
        return True
    algo.env_runner_group.foreach_env_runner(apply, local_env_runner=True)


def _to_tensors(value):
    """RLlib's optimizer state (numpy arrays, floats) as what a weights-only load reads."""
    if isinstance(value, dict):
        return {k: _to_tensors(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_tensors(v) for v in value]
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.array(value))
    return value


def _from_tensors(value):
    if isinstance(value, dict):
        return {(int(k) if isinstance(k, str) and k.isdigit() else k): _from_tensors(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_from_tensors(v) for v in value]
    if isinstance(value, torch.Tensor):
        return value.numpy()
    return value


# ----------------------------------------------------------------------------- the run
class RLlibRun:
    """One ``--backend rllib`` training run over ``out_dir`` (see the module docstring)."""

    def __init__(self, task, db, task_config, cfg: RLlibConfig, out_dir: Path, *, callbacks: Sequence[Any] = (),
                 address: Optional[str] = None, resume: bool = False):
        cfg.check()
        self.task, self.db, self.task_config, self.cfg = task, db, task_config, cfg
        self.out_dir = Path(out_dir)
        self.callbacks = list(callbacks)
        self.resume = resume
        probe = task.make_vector_env(1, db=db, config=task_config, num_threads=1)
        self.obs_dim, self.act_dim = probe.obs_dim, probe.act_dim
        space = probe.single_action_space
        self.action_center = ((space.high + space.low) / 2).astype(np.float32) if cfg.normalize_actions else None
        self.action_half = ((space.high - space.low) / 2).astype(np.float32) if cfg.normalize_actions else None
        torch.manual_seed(cfg.seed)
        if cfg.torch_threads > 0:
            torch.set_num_threads(cfg.torch_threads)
        factory = task_policy_factory(task)
        if factory is not None:
            self.model = factory(probe)(self.obs_dim, self.act_dim)
        else:
            from ...rl.networks import PlaneActorCritic
            self.model = PlaneActorCritic(self.obs_dim, self.act_dim, init_log_std=cfg.init_log_std)
        probe.close()
        self.resources = init_ray(address, cfg.workers)
        register_envs()
        self.db_handle = share_database(db)
        self.algo = build_algorithm(task, self.db_handle, task_config, cfg, self.obs_dim, self.act_dim, self.model,
                                    cpus_per_worker(self.resources, cfg.workers))
        self.global_step, self.iteration, self.wall_s = 0, 0, 0.0
        self.snapshots: set = set()
        if resume and (self.out_dir / "latest.pt").exists():  # killed before its first checkpoint: start over
            self._load(self.out_dir / "latest.pt")
        self._push_stage()

    # -- checkpoints -------------------------------------------------------------------------
    def checkpoint_state(self) -> dict:
        net = _net(self.algo)
        stats = _filter_stats(self.algo) if self.cfg.obs_filter else None
        if stats is None:  # no filter: the identity normalization
            stats = {"mean": np.zeros(self.obs_dim), "var": np.ones(self.obs_dim), "count": 1e-4}
        optimizer = _learner(self.algo).get_state(components="optimizer")
        return {
            "model": {k: v.detach().cpu().clone() for k, v in net.state_dict().items()},
            "model_class": network_name(net), "model_kwargs": dict(getattr(net, "init_kwargs", {})),
            # RLlib's MeanStdFilter: (x - mean) / (std + 1e-8), clipped at 10, with the unbiased
            # variance; load_policy's normalizer applies the same map up to the epsilon.
            "obs_normalizer": {"rms": {"mean": torch.from_numpy(stats["mean"]), "var": torch.from_numpy(stats["var"]),
                                       "count": float(stats["count"])},
                               "enabled": bool(self.cfg.obs_filter), "clip": 10.0,
                               "exclude": None if self.cfg.obs_filter_exclude is None
                               else [int(v) for v in self.cfg.obs_filter_exclude]},
            "action_center": None if self.action_center is None else self.action_center.tolist(),
            "action_half": None if self.action_half is None else self.action_half.tolist(),
            "global_step": self.global_step, "iteration": self.iteration, "wall_s": self.wall_s,
            "snapshots": sorted(self.snapshots), "backend": "rllib", "config": dataclasses.asdict(self.cfg),
            "rllib_optimizer": _to_tensors(optimizer),
            "callbacks": {i: cb.state_dict() for i, cb in enumerate(self.callbacks) if hasattr(cb, "state_dict")},
        }

    def save(self, snapshot_steps: Sequence[int] = ()) -> None:
        state = self.checkpoint_state()
        save_checkpoint(state, self.out_dir / "latest.pt")
        for s in snapshot_steps:
            save_checkpoint(state, self.out_dir / f"snapshot_{s}.pt")

    def _load(self, path: Path) -> None:
        state = load_checkpoint(path)
        if state.get("backend") != "rllib":
            raise InputError(f"{path}: written by mmrl's own trainer; resume it without --backend rllib")
        try:
            net = _net(self.algo)
            net.load_state_dict(state["model"])
            learner = _learner(self.algo)
            learner.set_state({"optimizer": _from_tensors(state["rllib_optimizer"])["optimizer"]})
        except Exception as e:
            raise InputError(f"{path}: does not fit this run's network or RLlib settings ({e})") from e
        self.algo.env_runner_group.sync_weights(from_worker_or_learner_group=self.algo.learner_group)
        if self.cfg.obs_filter:
            rms = state["obs_normalizer"]["rms"]
            _set_filter_stats(self.algo, {"mean": rms["mean"].numpy(), "var": rms["var"].numpy(),
                                          "count": rms["count"]})
        self.global_step, self.iteration, self.wall_s = state["global_step"], state["iteration"], state["wall_s"]
        self.snapshots = set(state["snapshots"])
        for i, cb in enumerate(self.callbacks):
            if hasattr(cb, "load_state_dict") and i in state["callbacks"]:
                cb.load_state_dict(state["callbacks"][i])

    # -- curriculum --------------------------------------------------------------------------
    def _push_stage(self) -> None:
        """Every worker (restarted ones too) at the curriculum's current stage."""
        for cb in self.callbacks:
            if hasattr(cb, "stage_params"):
                apply = set_worker_stage(cb.stage_params(cb.stage), cb.stage)
                self.algo.env_runner_group.foreach_env_runner(apply, local_env_runner=self.cfg.workers == 0)

    # -- one iteration -----------------------------------------------------------------------
    def _drain(self) -> Dict[str, Any]:
        logs = self.algo.env_runner_group.foreach_env_runner(drain_worker, local_env_runner=self.cfg.workers == 0)
        out: Dict[str, Any] = {"returns": [], "lengths": [], "success": [], "stages": [],
                               "match": {"decisions": 0, "transitions": 0, "cost_sum": 0.0, "frames": 0}}
        for worker in logs:
            for log in worker or []:
                for key in ("returns", "lengths", "success", "stages"):
                    out[key].extend(log[key])
                for key in out["match"]:
                    out["match"][key] += log["match"][key]
        return out

    def _row(self, result: dict, episodes: Dict[str, Any], steps: int, seconds: float) -> dict:
        learner = result.get("learners", {}).get("default_policy", {})
        runners = result.get("env_runners", {})
        r, l, s = (np.asarray(episodes[k], np.float64) for k in ("returns", "lengths", "success"))
        net = _net(self.algo)
        match = episodes["match"]
        sample_s = float(runners.get("sample", float("nan")))
        row = {
            "step": self.global_step, "wall_s": round(self.wall_s, 4), "iteration": self.iteration,
            "episode_return": float(r.mean()) if len(r) else float("nan"),
            "episode_length": float(l.mean()) if len(l) else float("nan"),
            "success_rate": float(s.mean()) if len(s) else float("nan"), "episodes": int(len(r)),
            "sps": round(steps / max(seconds, 1e-9), 1),
            "learning_rate": float(learner.get("default_optimizer_learning_rate", self.cfg.lr)),
            "policy_loss": float(learner.get("policy_loss", float("nan"))),
            "value_loss": float(learner.get("vf_loss", float("nan"))),
            "entropy": float(net.log_std.detach().sum() + 0.5 * self.act_dim * (1.0 + LOG_2PI)),
            "approx_kl": float(learner.get("mean_kl_loss", float("nan"))),
            "clipfrac": float("nan"),  # RLlib does not report it
            "explained_variance": float(learner.get("vf_explained_var", float("nan"))),
            # Per env step: time in RLlib's sampling (env + connectors + inference) and the rest.
            "env_us": 1e6 * sample_s / max(steps, 1) if math.isfinite(sample_s) else float("nan"),
            "act_us": float("nan"),
            "update_us": 1e6 * float(result.get("timers", {}).get("learner_update", float("nan"))) / max(steps, 1),
            "transitions_per_s": (rate_per_second(match["transitions"], match["frames"], self.db.fps)
                                  if match["decisions"] else float("nan")),
            "matched_cost": match["cost_sum"] / match["decisions"] if match["decisions"] else float("nan"),
        }
        for cb in self.callbacks:
            if hasattr(cb, "record"):
                cb.record(episodes["success"], episodes["stages"])
            if hasattr(cb, "on_iteration"):
                before = getattr(cb, "stage", None)
                row.update(cb.on_iteration({"step": self.global_step}) or {})
                if getattr(cb, "stage", None) != before:
                    self._push_stage()
        return row

    def train(self) -> dict:
        """Iterate until the step or time budget; returns the last metrics row."""
        cfg = self.cfg
        log = MetricsLogger(self.out_dir, self.global_step if self.resume else None, cfg.tensorboard)
        progress = ProgressBar(cfg.total_steps, cfg.max_seconds, self.global_step, self.wall_s) if cfg.progress else None
        last_saved, row = self.global_step, {}
        start, offset = time.perf_counter(), self.wall_s
        try:
            while self.global_step < cfg.total_steps and (cfg.max_seconds is None or self.wall_s < cfg.max_seconds):
                t0 = time.perf_counter()
                result = self._train_once()
                episodes = self._drain()
                steps = int(result.get("env_runners", {}).get("num_env_steps_sampled", 0)) or cfg.batch_size()
                self.global_step += steps
                self.iteration += 1
                self.wall_s = offset + (time.perf_counter() - start)
                row = self._row(result, episodes, steps, time.perf_counter() - t0)
                log.write(row)
                if progress is not None:
                    progress.update(self.global_step, self.wall_s, row)
                due = [s for s in cfg.snapshot_steps if s <= self.global_step and s not in self.snapshots]
                if due or self.global_step - last_saved >= cfg.checkpoint_interval_steps:
                    self.snapshots.update(due)
                    self.save(due)
                    last_saved = self.global_step
            self.save()
        except (KeyboardInterrupt, WorkerLost):
            self.save()  # the learner is whole: keep every completed iteration for --resume
            raise
        finally:
            if progress is not None:
                progress.close()
            log.close()
        return row

    def _train_once(self) -> dict:
        try:
            result = self.algo.train()
        except Exception as e:
            if "EnvRunner" in type(e).__name__ or "ActorDied" in type(e).__name__ or "RayActorError" in repr(type(e)):
                raise WorkerLost(f"an RLlib worker died and could not be restarted ({type(e).__name__}); "
                                 f"latest.pt holds step {self.global_step:,} of the run") from e
            raise
        healthy = self.algo.env_runner_group.num_healthy_remote_workers() if self.cfg.workers else 0
        if self.cfg.workers and healthy == 0:
            raise WorkerLost(f"every RLlib worker is dead (restarts exhausted: max_worker_restarts="
                             f"{self.cfg.max_worker_restarts}); latest.pt holds step {self.global_step:,}")
        self._push_stage()  # a restarted worker starts at the config's stage (a no-op without a curriculum)
        return result

    def worker_pids(self) -> List[int]:
        return [p for p in self.algo.env_runner_group.foreach_env_runner(lambda r: os.getpid(), local_env_runner=False)]

    def stop(self) -> None:
        self.algo.stop()
