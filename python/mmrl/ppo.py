"""Proximal Policy Optimization for gymnasium 1.x vector envs, in one file.

Reads top to bottom: the config, small helpers (running statistics, GAE,
checkpoints), the policy loader used by ``mmrl eval``/``render``, then
``train`` with one flat loop: collect a rollout, compute advantages, update.

The env contract (what the mmrl envs provide, and ``tests/_toyenv.py``):

- a ``gymnasium.vector.VectorEnv`` with a flat float32 ``Box`` observation
  (num_envs, obs_dim) and a ``Box`` action; the env clips actions to its box;
- ``metadata["autoreset_mode"] == AutoresetMode.SAME_STEP``: the obs returned
  with a done flag is already the next episode's first obs, and the last obs of
  the finished episode is in ``infos["final_obs"]`` (mask ``infos["_final_obs"]``);
- ``infos["success"]`` (bool, (num_envs,)) with mask ``infos["_success"]`` on
  the steps where episodes end. Without it, success_rate is NaN.

Design choices, and why:

- Values are computed after the rollout for all observations in one batched
  call, not per step: acting then runs only the policy MLP.
- Observation statistics are frozen during a rollout and updated from the
  whole rollout afterwards, so the update sees exactly the inputs the policy
  acted on, and acting costs one fused multiply-add for normalization.
- Truncation bootstraps with the value of ``infos["final_obs"]``; termination
  does not bootstrap (see ``compute_gae``).
- Everything random in PPO (action noise, minibatch order) comes from one CPU
  ``torch.Generator``, so CPU and CUDA runs sample the same noise. On CUDA, a
  few kernels (atomics in backward of some ops) may still make runs differ in
  the last bits; on CPU the same seed gives bit-identical metrics.
"""
from __future__ import annotations

import csv
import dataclasses
import importlib
import math
import os
import random
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal, Optional, Sequence

import gymnasium as gym
import numpy as np
import torch
from torch import nn

__all__ = [
    "PPOConfig", "TrainResult", "train", "load_policy", "Policy", "compute_gae", "successor_values",
    "CheckpointError", "NonFiniteError", "save_checkpoint", "load_checkpoint",
]

CHECKPOINT_FORMAT = "mmrl-ppo-checkpoint"
CHECKPOINT_VERSION = 1


# ----------------------------------------------------------------------------- config

@dataclass
class PPOConfig:
    """Everything that shapes a PPO run. Defaults are tuned for the plane task's
    reward (exp(-dist) every step plus a sparse +1000 success bonus) on 2 CPU
    cores; see the docs of each field."""

    seed: int = 0
    """Seeds python, numpy, torch, PPO's sampling generator and ``envs.reset``."""

    total_steps: int = 1_000_000
    """Stop after this many env steps (summed over envs); whichever of this and
    ``max_seconds`` comes first."""

    max_seconds: Optional[float] = None
    """Wall-clock training budget in seconds (training time only, excluding setup
    and checkpoint loading). None means no time limit. Checked between
    iterations, so a run may overshoot by one iteration."""

    num_steps: int = 32
    """Steps per env per rollout. The batch is ``num_steps * num_envs``. Short
    rollouts mean more updates per env step: on the toy target task, 32 reached
    95% success in about half the env steps of 64 (the env, not the update,
    dominates the cost of a step in the real tasks)."""

    learning_rate: float = 2e-3
    """Adam step size. Tiny 32 x 32 networks tolerate a larger rate than the
    usual 3e-4, and learn faster with it (plane task on the shared data, seed 0:
    95% deterministic success after ~5 s at 2e-3 with 8 epochs, ~16 s at 1e-3 with 4)."""

    anneal_lr: bool = False
    """Linearly decay the learning rate to zero over ``total_steps`` (by steps,
    never by wall time, to stay reproducible)."""

    gamma: float = 0.99
    """Discount factor."""

    gae_lambda: float = 0.95
    """GAE lambda (RLlib's default is 1.0; 0.95 trades a little bias for less
    variance from the sparse bonus)."""

    clip_coef: float = 0.2
    """PPO ratio clipping epsilon."""

    clip_vloss: bool = False
    """Clip the value update around the old values by ``clip_coef`` (in value
    units). Off by default: with a +1000 bonus the value must move a lot."""

    ent_coef: float = 0.0
    """Entropy bonus coefficient. The log-std is a free parameter, so any
    positive value pushes it up with a constant gradient; 0 as in RLlib."""

    vf_coef: float = 0.5
    """Value loss coefficient. Policy and value networks share no weights, so
    this only rescales the value gradient relative to Adam's normalization."""

    max_grad_norm: float = 0.5
    """Clip the global gradient norm to this (None disables)."""

    update_epochs: int = 8
    """Passes over each rollout batch. The plane task's env step (a motion-matching
    search) costs more than an update pass of the tiny networks, so squeezing more out of
    each sample pays in wall time."""

    num_minibatches: int = 4
    """Minibatches per epoch; the minibatch size is batch / num_minibatches.
    Few, large minibatches keep the update cheap on CPU (torch overhead per call
    dominates the tiny networks)."""

    norm_adv: bool = True
    """Standardize advantages per minibatch."""

    target_kl: Optional[float] = None
    """Stop the epochs of an update early once the approximate KL exceeds this.
    None disables."""

    obs_norm: bool = True
    """Normalize observations by a running mean and std (saved in checkpoints
    and applied by ``load_policy``). Statistics are frozen during a rollout and
    updated after it; the first rollout sees raw observations."""

    obs_norm_exclude: Optional[tuple[int, int]] = None
    """A (start, stop) range of flat observation entries left unnormalized,
    e.g. the binary sensor maps of the obstacle task
    (``ObstacleActorCritic.map_range(layout)``)."""

    obs_clip: float = 10.0
    """Clip normalized observations to [-obs_clip, obs_clip]."""

    reward_norm: Literal["scale", "value", "none"] = "scale"
    """How to tame the +1000 bonus. "scale": divide rewards by a running std of
    the discounted return (the PPO implementation-details trick). "value":
    keep rewards raw but train the value net on returns standardized by a
    running mean/std. "none": raw rewards. "scale" learned fastest on the toy
    target task (see the module's tests and the branch report)."""

    reward_clip: Optional[float] = None
    """Clip scaled rewards to [-reward_clip, reward_clip]; None keeps the bonus
    intact (clipping at the common 10 would flatten a +1000 bonus)."""

    init_log_std: float = 0.0
    """Initial log standard deviation of the Gaussian policy (in the policy's action units;
    with ``rescale_actions`` 0 means one box half-width). Used by the default network."""

    rescale_actions: bool = True
    """When the env's action Box is finite, the policy acts in standardized units:
    env action = center + half_width * a, so a = +-1 reaches the box's faces and the
    initial exploration (std 1) spans the box in every dimension, however different the
    dimensions' ranges. The mmrl tasks' boxes (normalized trajectory features, +-3 std per
    dimension) differ by 10x between dimensions; without this, exploration is far too wide
    in the narrow ones. Saved in checkpoints and applied by ``load_policy``."""

    device: str = "auto"
    """"auto" = CUDA if available, else CPU; or any torch device string."""

    torch_threads: int = 1
    """``torch.set_num_threads`` for the run (0 leaves torch's setting). One
    thread is fastest for 32 x 32 networks and leaves the other core to the
    C++ env; the obstacle CNN prefers 2 (measure)."""

    log_interval: int = 1
    """Write CSV/TensorBoard rows every this many iterations."""

    tensorboard: bool = True
    """Also log to TensorBoard event files in out_dir."""

    progress: bool = True
    """Show a tqdm progress bar."""

    checkpoint_interval_steps: int = 100_000
    """Rewrite ``latest.pt`` whenever this many env steps passed since the last
    save (and always at the end of training)."""

    snapshot_steps: tuple[int, ...] = ()
    """Also keep ``snapshot_<N>.pt`` the first time the global step reaches each
    N, e.g. (20_000, 100_000, 533_000, 1_000_000) for the paper's Figure 4."""

    def __post_init__(self) -> None:
        if self.num_steps < 1 or self.update_epochs < 1 or self.num_minibatches < 1:
            raise ValueError("PPOConfig: num_steps, update_epochs and num_minibatches must be >= 1")
        if self.reward_norm not in ("scale", "value", "none"):
            raise ValueError(f"PPOConfig: reward_norm must be 'scale', 'value' or 'none', got {self.reward_norm!r}")
        self.snapshot_steps = tuple(int(s) for s in self.snapshot_steps)
        if self.obs_norm_exclude is not None:
            self.obs_norm_exclude = (int(self.obs_norm_exclude[0]), int(self.obs_norm_exclude[1]))


@dataclass
class TrainResult:
    """What ``train`` returns."""

    global_step: int
    wall_s: float
    iterations: int
    stopped_by: str
    """"steps" or "seconds"."""
    last_stats: dict
    """The scalar metrics of the last logged iteration."""
    checkpoint: Path
    metrics_csv: Path


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, corrupt, or not an mmrl PPO checkpoint."""


class NonFiniteError(RuntimeError):
    """NaN or inf in observations, actions, rewards or the loss."""


# ----------------------------------------------------------------------------- running statistics

class RunningMeanStd:
    """Mean and variance of a stream of batches (parallel Welford), in float64."""

    def __init__(self, shape: tuple[int, ...] = ()):
        self.mean = np.zeros(shape, np.float64)
        self.var = np.ones(shape, np.float64)
        self.count = 1e-4

    def update(self, batch: np.ndarray) -> None:
        batch = np.asarray(batch, np.float64).reshape(-1, *self.mean.shape)
        batch_mean, batch_var, batch_count = batch.mean(0), batch.var(0), batch.shape[0]
        delta = batch_mean - self.mean
        total = self.count + batch_count
        self.mean = self.mean + delta * batch_count / total
        m2 = self.var * self.count + batch_var * batch_count + delta**2 * self.count * batch_count / total
        self.var = m2 / total
        self.count = total

    def state_dict(self) -> dict:
        return {"mean": torch.from_numpy(np.array(self.mean, np.float64)),
                "var": torch.from_numpy(np.array(self.var, np.float64)),
                "count": float(self.count)}

    def load_state_dict(self, state: dict) -> None:
        self.mean = state["mean"].numpy().astype(np.float64)
        self.var = state["var"].numpy().astype(np.float64)
        self.count = float(state["count"])


class ObsNormalizer:
    """Running observation statistics plus the frozen torch affine map used to act:
    normalized = clamp(obs * scale + shift, -clip, clip)."""

    def __init__(self, obs_dim: int, enabled: bool, exclude: Optional[tuple[int, int]], clip: float,
                 device: torch.device):
        self.rms = RunningMeanStd((obs_dim,))
        self.enabled, self.exclude, self.clip = enabled, exclude, clip
        self.scale = torch.ones(obs_dim, device=device)
        self.shift = torch.zeros(obs_dim, device=device)

    def refresh(self) -> None:
        """Copy the running statistics into the frozen affine map."""
        if not self.enabled:
            return
        scale = 1.0 / np.sqrt(self.rms.var + 1e-8)
        shift = -self.rms.mean * scale
        if self.exclude is not None:
            scale[self.exclude[0]:self.exclude[1]] = 1.0
            shift[self.exclude[0]:self.exclude[1]] = 0.0
        self.scale.copy_(torch.from_numpy(scale.astype(np.float32)))
        self.shift.copy_(torch.from_numpy(shift.astype(np.float32)))

    def __call__(self, obs: torch.Tensor) -> torch.Tensor:
        if not self.enabled:
            return obs
        return torch.addcmul(self.shift, obs, self.scale).clamp_(-self.clip, self.clip)

    def state_dict(self) -> dict:
        return {"rms": self.rms.state_dict(), "enabled": self.enabled, "exclude": self.exclude,
                "clip": self.clip}

    def load_state_dict(self, state: dict) -> None:
        self.rms.load_state_dict(state["rms"])
        self.enabled, self.clip = bool(state["enabled"]), float(state["clip"])
        self.exclude = tuple(state["exclude"]) if state["exclude"] is not None else None
        self.refresh()


# ----------------------------------------------------------------------------- advantages

def successor_values(values: np.ndarray, terminated: np.ndarray, truncations: Sequence[tuple[int, np.ndarray]],
                     final_values: np.ndarray) -> np.ndarray:
    """Values of each step's true successor state, for ``compute_gae``.

    ``values`` (T + 1, N) are the values of the rollout's observations, row T
    being the obs after the last step. ``truncations`` lists (t, env indices)
    of episodes truncated at step t, in order; ``final_values`` holds the
    values of their ``final_obs``, concatenated in the same order. Terminated
    steps get 0 (no bootstrapping), truncated ones the value of the final obs,
    all others the value of the next obs in the rollout.
    """
    next_values = values[1:].copy()
    offset = 0
    for t, envs_idx in truncations:
        next_values[t, envs_idx] = final_values[offset:offset + len(envs_idx)]
        offset += len(envs_idx)
    next_values[terminated] = 0.0
    return next_values


def compute_gae(rewards: np.ndarray, values: np.ndarray, next_values: np.ndarray, episode_ends: np.ndarray,
                gamma: float, gae_lambda: float) -> tuple[np.ndarray, np.ndarray]:
    """Generalized advantage estimation over a (T, N) rollout.

    ``next_values[t]`` is the value of the true successor of step t: the next
    obs in the rollout; the value of ``infos["final_obs"]`` if the episode was
    truncated at t; 0 if it terminated at t. ``episode_ends[t]`` (terminated or
    truncated) cuts the lambda-chain, because the next row of the rollout is a
    new episode. Returns (advantages, returns = advantages + values).
    """
    advantages = np.zeros_like(values, dtype=np.float64)
    last = np.zeros(values.shape[1:], np.float64)
    continues = 1.0 - episode_ends.astype(np.float64)
    for t in reversed(range(values.shape[0])):
        delta = rewards[t] + gamma * next_values[t] - values[t]
        last = delta + gamma * gae_lambda * continues[t] * last
        advantages[t] = last
    return advantages, advantages + values


def scale_rewards(rewards: np.ndarray, episode_ends: np.ndarray, running_return: np.ndarray,
                  rms: RunningMeanStd, gamma: float, clip: Optional[float]) -> np.ndarray:
    """Divide a (T, N) rollout of rewards by the running std of discounted returns.

    ``running_return`` (N,) carries the discounted return across rollouts and is
    updated in place; it restarts at episode ends.
    """
    returns = np.empty_like(rewards, dtype=np.float64)
    for t in range(rewards.shape[0]):
        running_return *= gamma
        running_return += rewards[t]
        returns[t] = running_return
        running_return[episode_ends[t]] = 0.0
    rms.update(returns.reshape(-1))
    scaled = rewards / math.sqrt(float(rms.var) + 1e-8)
    if clip is not None:
        scaled = np.clip(scaled, -clip, clip)
    return scaled


# ----------------------------------------------------------------------------- checkpoints

def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return  # not supported (e.g. Windows); the rename is still atomic
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def save_checkpoint(state: dict, path: str | os.PathLike) -> Path:
    """Write ``state`` atomically: a temp file in the same directory, fsync, rename.

    If anything fails, the file already at ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **state}
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as file:
            torch.save(payload, file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp_name, path)
    except BaseException:
        if os.path.exists(tmp_name):
            os.unlink(tmp_name)
        raise
    _fsync_dir(path.parent)
    return path


def load_checkpoint(path: str | os.PathLike, map_location: Any = "cpu") -> dict:
    """Load and validate a checkpoint; raise ``CheckpointError`` naming the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as error:  # torch raises several types for truncated or foreign files
        raise CheckpointError(f"{path}: not a readable checkpoint (corrupt or truncated?): {error}") from error
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not an mmrl PPO checkpoint")
    if state.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: checkpoint version {state.get('version')} is not supported "
                              f"(expected {CHECKPOINT_VERSION})")
    return state


def _class_path(obj: object) -> str:
    return f"{type(obj).__module__}:{type(obj).__qualname__}"


def _build_model(class_path: str, kwargs: dict) -> nn.Module:
    module_name, _, qualname = class_path.partition(":")
    target: Any = importlib.import_module(module_name)
    for part in qualname.split("."):
        target = getattr(target, part)
    return target(**kwargs)


def _rng_state() -> dict:
    np_state = np.random.get_state()
    return {
        "python": random.getstate(),
        "numpy": {"keys": torch.from_numpy(np_state[1].astype(np.int64)), "pos": int(np_state[2]),
                  "has_gauss": int(np_state[3]), "cached_gaussian": float(np_state[4])},
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
    }


def _set_rng_state(state: dict) -> None:
    random.setstate(_as_tuple(state["python"]))
    np_state = state["numpy"]
    np.random.set_state(("MT19937", np_state["keys"].numpy().astype(np.uint32), np_state["pos"],
                         np_state["has_gauss"], np_state["cached_gaussian"]))
    torch.set_rng_state(state["torch"])
    if state["cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def _as_tuple(value: Any) -> Any:
    return tuple(_as_tuple(v) for v in value) if isinstance(value, (list, tuple)) else value


# ----------------------------------------------------------------------------- acting with a saved policy

class Policy:
    """A trained policy for evaluation and rendering: applies the saved
    observation normalization, then the Gaussian mean (deterministic) or a sample."""

    def __init__(self, model: nn.Module, obs_normalizer: ObsNormalizer, device: torch.device,
                 action_center: Optional[np.ndarray] = None, action_half: Optional[np.ndarray] = None):
        self.model = model.eval()
        self.obs_normalizer = obs_normalizer
        self.device = device
        self.action_center = action_center
        self.action_half = action_half

    @torch.inference_mode()
    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """obs (obs_dim,) or (B, obs_dim) -> actions (act_dim,) or (B, act_dim), float32."""
        obs = np.asarray(obs, np.float32)
        single = obs.ndim == 1
        obs_t = torch.as_tensor(obs.reshape(1, -1) if single else obs, device=self.device)
        if not torch.isfinite(obs_t).all():
            raise NonFiniteError("Policy.act: observation contains NaN or inf")
        mean = self.model.actor_mean(self.obs_normalizer(obs_t))
        if not deterministic:
            mean = mean + self.model.log_std.exp() * torch.randn_like(mean)
        actions = mean.float().cpu().numpy()
        if self.action_center is not None:
            actions = (self.action_center + self.action_half * actions).astype(np.float32)
        return actions[0] if single else actions


def load_policy(path: str | os.PathLike, device: str = "cpu") -> Policy:
    """Rebuild the policy saved in a checkpoint written by ``train``."""
    device_t = _resolve_device(device)
    state = load_checkpoint(path)
    try:
        model = _build_model(state["model_class"], state["model_kwargs"]).to(device_t)
        model.load_state_dict(state["model"])
    except Exception as error:
        raise CheckpointError(f"{path}: cannot rebuild the network: {error}") from error
    obs_dim = state["obs_normalizer"]["rms"]["mean"].shape[0]
    normalizer = ObsNormalizer(obs_dim, True, None, 10.0, device_t)
    normalizer.load_state_dict(state["obs_normalizer"])
    center, half = state.get("action_center"), state.get("action_half")
    return Policy(model, normalizer, device_t,
                  None if center is None else np.asarray(center, np.float32),
                  None if half is None else np.asarray(half, np.float32))


# ----------------------------------------------------------------------------- training

def _resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


def _default_policy_factory(obs_dim: int, act_dim: int, init_log_std: float = 0.0) -> nn.Module:
    from .networks import PlaneActorCritic
    return PlaneActorCritic(obs_dim, act_dim, init_log_std=init_log_std)


def _check_env(envs: gym.vector.VectorEnv) -> tuple[int, int]:
    mode = envs.metadata.get("autoreset_mode")
    if mode != gym.vector.AutoresetMode.SAME_STEP:
        raise ValueError(f"train: the env must use AutoresetMode.SAME_STEP, its metadata says {mode!r}")
    obs_space, act_space = envs.single_observation_space, envs.single_action_space
    if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape) != 1:
        raise ValueError(f"train: expected a flat Box observation space, got {obs_space}")
    if not isinstance(act_space, gym.spaces.Box) or len(act_space.shape) != 1:
        raise ValueError(f"train: expected a flat Box action space, got {act_space}")
    return obs_space.shape[0], act_space.shape[0]


def _final_obs_rows(infos: dict, envs_idx: np.ndarray) -> np.ndarray:
    if "final_obs" not in infos:
        raise ValueError("train: an episode was truncated but infos has no 'final_obs' (SAME_STEP contract)")
    final_obs = infos["final_obs"]
    if final_obs.dtype == object:  # gymnasium's SyncVectorEnv stores one array per env
        return np.stack([np.asarray(final_obs[i], np.float32) for i in envs_idx])
    return np.asarray(final_obs[envs_idx], np.float32)


class _MetricsLog:
    """metrics.csv (appended on resume) plus an optional TensorBoard writer."""

    BASE_COLUMNS = ("step", "wall_s", "iteration", "episode_return", "episode_length", "success_rate",
                    "episodes", "sps", "learning_rate", "policy_loss", "value_loss", "entropy", "approx_kl",
                    "clipfrac", "explained_variance", "env_us", "act_us", "update_us")

    def __init__(self, out_dir: Path, resume_step: Optional[int], tensorboard: bool):
        self.path = out_dir / "metrics.csv"
        self.columns: Optional[list[str]] = None
        if resume_step is not None and self.path.exists():
            # Drop rows logged after the checkpoint we resume from.
            with open(self.path, newline="") as file:
                rows = list(csv.reader(file))
            if rows:
                self.columns = rows[0]
                kept = [rows[0]] + [r for r in rows[1:] if r and int(float(r[0])) <= resume_step]
                if len(kept) != len(rows):
                    tmp = self.path.with_suffix(".csv.tmp")
                    with open(tmp, "w", newline="") as file:
                        csv.writer(file).writerows(kept)
                    os.replace(tmp, self.path)
        self.file = open(self.path, "a", newline="")
        self.writer: Optional[csv.DictWriter] = None
        if self.columns is not None:
            self.writer = csv.DictWriter(self.file, self.columns, extrasaction="ignore")
        self.tb = None
        if tensorboard:
            from torch.utils.tensorboard import SummaryWriter
            self.tb = SummaryWriter(str(out_dir))

    def write(self, row: dict) -> None:
        if self.writer is None:
            extra = [k for k in row if k not in self.BASE_COLUMNS]
            self.columns = list(self.BASE_COLUMNS) + extra
            self.writer = csv.DictWriter(self.file, self.columns, extrasaction="ignore")
            self.writer.writeheader()
        self.writer.writerow({k: row.get(k, "") for k in self.columns})
        self.file.flush()
        if self.tb is not None:
            step = int(row["step"])
            for key, value in row.items():
                if key in ("step", "iteration") or not np.isfinite(value):
                    continue
                group = "time" if key.endswith("_us") else "losses" if key in ("policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac",
                                            "explained_variance") else "charts"
                name = {"sps": "SPS"}.get(key, key)
                self.tb.add_scalar(f"{group}/{name}", value, step)

    def close(self) -> None:
        self.file.close()
        if self.tb is not None:
            self.tb.close()


def train(envs: gym.vector.VectorEnv, cfg: PPOConfig, out_dir: str | os.PathLike, *,
          policy_factory: Optional[Callable[[int, int], nn.Module]] = None, resume: bool = False,
          callbacks: Sequence[Any] | None = None) -> TrainResult:
    """Train a Gaussian policy with PPO on ``envs``; write metrics and checkpoints to ``out_dir``.

    ``policy_factory(obs_dim, act_dim)`` builds the actor-critic (default: the
    paper's ``PlaneActorCritic``); see ``mmrl.networks`` for the interface.
    ``resume=True`` continues from ``out_dir/latest.pt``: model, optimizer,
    normalizers, step, wall time, RNG and callback state. The envs are reset
    (their state is not checkpointed) with seed ``cfg.seed + global_step``.
    ``callbacks``: objects with any of ``on_iteration(stats) -> dict | None``
    (extra scalar columns for CSV/TensorBoard), ``state_dict()`` and
    ``load_state_dict(state)`` (stored in checkpoints under their index).
    ``stats`` holds the iteration's scalars plus ``stats["episodes"]``, a dict
    of arrays "return", "length", "success" for the episodes that ended.
    """
    callbacks = list(callbacks or [])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    latest_path = out_dir / "latest.pt"
    if not resume and latest_path.exists():
        raise FileExistsError(f"{out_dir} already holds a run ({latest_path}); pass resume=True or use a new directory")
    obs_dim, act_dim = _check_env(envs)
    action_center = action_half = None
    space = envs.single_action_space
    if cfg.rescale_actions and np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)):
        action_center = ((space.high + space.low) / 2).astype(np.float32)
        action_half = ((space.high - space.low) / 2).astype(np.float32)
    num_envs, T = envs.num_envs, cfg.num_steps
    batch_size = T * num_envs
    minibatch_size = max(1, batch_size // cfg.num_minibatches)
    device = _resolve_device(cfg.device)
    if cfg.torch_threads > 0:
        torch.set_num_threads(cfg.torch_threads)

    # Seeding. PPO's own sampling uses a CPU generator so devices agree.
    random.seed(cfg.seed)
    np.random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    generator = torch.Generator().manual_seed(cfg.seed)

    if policy_factory is None:
        model = _default_policy_factory(obs_dim, act_dim, cfg.init_log_std).to(device)
    else:
        model = policy_factory(obs_dim, act_dim).to(device)
    # The fused Adam kernel (CPU and CUDA, torch >= 2.4) is ~7x cheaper per step
    # than the default for-loop on these tiny networks.
    try:
        optimizer = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5, fused=True)
    except (RuntimeError, TypeError):
        optimizer = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5)
    obs_normalizer = ObsNormalizer(obs_dim, cfg.obs_norm, cfg.obs_norm_exclude, cfg.obs_clip, device)
    return_rms = RunningMeanStd()  # discounted returns ("scale") or value targets ("value")
    running_return = np.zeros(num_envs, np.float64)
    global_step, wall_offset, iteration = 0, 0.0, 0
    saved_snapshots: set[int] = set()

    if resume:
        state = load_checkpoint(latest_path)  # on the CPU: RNG states must stay there
        try:
            model.load_state_dict(state["model"])
            optimizer.load_state_dict(state["optimizer"])
        except Exception as error:
            raise CheckpointError(f"{latest_path}: does not fit this network/config: {error}") from error
        obs_normalizer.load_state_dict(state["obs_normalizer"])
        return_rms.load_state_dict(state["return_rms"])
        global_step, wall_offset, iteration = state["global_step"], state["wall_s"], state["iteration"]
        saved_snapshots = set(state["snapshots"])
        _set_rng_state(state["rng"])
        generator.set_state(state["rng"]["ppo_generator"])
        for i, callback in enumerate(callbacks):
            if hasattr(callback, "load_state_dict") and i in state["callbacks"]:
                callback.load_state_dict(state["callbacks"][i])

    def checkpoint_state(wall_s: float) -> dict:
        rng = _rng_state()
        rng["ppo_generator"] = generator.get_state()
        return {
            "model": model.state_dict(), "model_class": _class_path(model),
            "model_kwargs": getattr(model, "init_kwargs", {}),
            "optimizer": optimizer.state_dict(), "obs_normalizer": obs_normalizer.state_dict(),
            "return_rms": return_rms.state_dict(), "global_step": global_step, "wall_s": wall_s,
            "iteration": iteration, "snapshots": sorted(saved_snapshots), "rng": rng,
            "config": dataclasses.asdict(cfg),
            "action_center": None if action_center is None else action_center.tolist(),
            "action_half": None if action_half is None else action_half.tolist(),
            "callbacks": {i: cb.state_dict() for i, cb in enumerate(callbacks) if hasattr(cb, "state_dict")},
        }

    # Rollout storage lives on the CPU with numpy views, so env results are
    # written with one numpy copy; the batch moves to the device once per update.
    obs_buf = torch.zeros(T + 1, num_envs, obs_dim)
    obs_np = obs_buf.numpy()
    actions_buf = torch.zeros(T, num_envs, act_dim)
    rewards_np = np.zeros((T, num_envs), np.float64)
    terminated_np = np.zeros((T, num_envs), bool)
    truncated_np = np.zeros((T, num_envs), bool)
    episode_return = np.zeros(num_envs, np.float64)
    episode_length = np.zeros(num_envs, np.int64)

    obs, _ = envs.reset(seed=cfg.seed + global_step)
    obs_np[0] = obs
    log = _MetricsLog(out_dir, global_step if resume else None, cfg.tensorboard)
    last_checkpoint_step = global_step
    progress = None
    if cfg.progress:
        from tqdm.auto import tqdm
        progress = tqdm(total=cfg.total_steps, initial=min(global_step, cfg.total_steps), unit="step",
                        dynamic_ncols=True)
    log_2pi = math.log(2 * math.pi)
    last_row: dict = {}
    stopped_by = "steps"
    start_time = time.perf_counter()
    wall_s = previous_wall_s = wall_offset
    try:
        while global_step < cfg.total_steps:
            if cfg.max_seconds is not None and wall_s >= cfg.max_seconds:
                stopped_by = "seconds"
                break
            iteration += 1
            lr = cfg.learning_rate * (1.0 - global_step / cfg.total_steps if cfg.anneal_lr else 1.0)
            for group in optimizer.param_groups:
                group["lr"] = lr

            # ---------------------------------------------------------------- rollout
            rollout_start = time.perf_counter()
            env_seconds = 0.0
            noise = torch.randn(T, num_envs, act_dim, generator=generator)
            final_obs: list[tuple[int, np.ndarray, np.ndarray]] = []  # (t, env indices, obs) at truncations
            ended_returns, ended_lengths, ended_success = [], [], []
            with torch.inference_mode():
                std = model.log_std.exp().to(device)
                noise_dev = noise.to(device)
                for t in range(T):
                    mean = model.actor_mean(obs_normalizer(obs_buf[t].to(device, non_blocking=True)))
                    action = torch.addcmul(mean, std, noise_dev[t])
                    action_np = action.numpy() if device.type == "cpu" else action.cpu().numpy()
                    actions_buf[t] = torch.from_numpy(action_np) if device.type != "cpu" else action
                    if not np.isfinite(action_np).all():
                        raise NonFiniteError(f"train: the policy produced NaN/inf actions at step {global_step}")
                    env_start = time.perf_counter()
                    if action_center is not None:
                        action_np = action_center + action_half * action_np
                    obs, reward, terminated, truncated, infos = envs.step(action_np)
                    env_seconds += time.perf_counter() - env_start
                    if not np.isfinite(obs).all() or not np.isfinite(reward).all():
                        raise NonFiniteError(f"train: the env returned NaN/inf observations or rewards "
                                             f"at step {global_step}")
                    obs_np[t + 1] = obs
                    rewards_np[t] = reward
                    terminated_np[t] = terminated
                    truncated_np[t] = truncated
                    episode_return += reward
                    episode_length += 1
                    global_step += num_envs
                    done = terminated | truncated
                    if done.any():
                        ended = np.flatnonzero(done)
                        ended_returns.append(episode_return[ended].copy())
                        ended_lengths.append(episode_length[ended].copy())
                        if "success" in infos:
                            mask = infos.get("_success", np.ones(num_envs, bool))[ended]
                            ended_success.append(np.where(mask, infos["success"][ended].astype(np.float64), np.nan))
                        else:
                            ended_success.append(np.full(len(ended), np.nan))
                        episode_return[ended] = 0.0
                        episode_length[ended] = 0
                        cut = np.flatnonzero(truncated & ~terminated)
                        if len(cut):
                            final_obs.append((t, cut, _final_obs_rows(infos, cut)))

                # ------------------------------------------------------------ advantages
                all_obs = obs_normalizer(obs_buf.to(device).reshape(-1, obs_dim))
                values = model.value(all_obs).reshape(T + 1, num_envs).double().cpu().numpy()
                if final_obs:
                    stacked = torch.from_numpy(np.concatenate([rows for _, _, rows in final_obs])).to(device)
                    final_values = model.value(obs_normalizer(stacked)).double().cpu().numpy()
                if cfg.reward_norm == "value":  # the net predicts standardized returns
                    values = values * math.sqrt(float(return_rms.var) + 1e-8) + float(return_rms.mean)
                    if final_obs:
                        final_values = final_values * math.sqrt(float(return_rms.var) + 1e-8) + float(return_rms.mean)
                next_values = successor_values(values, terminated_np, [(t, cut) for t, cut, _ in final_obs],
                                               final_values if final_obs else np.zeros(0))
                episode_ends = terminated_np | truncated_np
                rewards = rewards_np
                if cfg.reward_norm == "scale":
                    rewards = scale_rewards(rewards_np, episode_ends, running_return, return_rms, cfg.gamma,
                                            cfg.reward_clip)
                advantages, returns = compute_gae(rewards, values[:-1], next_values, episode_ends, cfg.gamma,
                                                  cfg.gae_lambda)
                if cfg.reward_norm == "value":
                    return_rms.update(returns.reshape(-1))
                    value_scale = math.sqrt(float(return_rms.var) + 1e-8)
                    returns = (returns - float(return_rms.mean)) / value_scale
                    old_values = (values[:-1] - float(return_rms.mean)) / value_scale
                else:
                    old_values = values[:-1]

                b_obs = all_obs[:batch_size]  # rows of steps 0..T-1, normalized as when acting
                b_actions = actions_buf.reshape(batch_size, act_dim).to(device)
                b_noise = noise_dev.reshape(batch_size, act_dim)
                b_logprob = (-0.5 * b_noise.pow(2).sum(1) - model.log_std.sum() - 0.5 * act_dim * log_2pi)
                b_advantages = torch.from_numpy(advantages.reshape(-1).astype(np.float32)).to(device)
                b_returns = torch.from_numpy(returns.reshape(-1).astype(np.float32)).to(device)
                b_values = torch.from_numpy(old_values.reshape(-1).astype(np.float32)).to(device)

            # Update the observation statistics from this rollout, for the next one.
            if cfg.obs_norm:
                obs_normalizer.rms.update(obs_np[1:].reshape(-1, obs_dim))
                obs_normalizer.refresh()

            # ---------------------------------------------------------------- update
            update_start = time.perf_counter()
            # Clone out of inference mode so autograd may use them.
            b_obs, b_actions, b_logprob = b_obs.clone(), b_actions.clone(), b_logprob.clone()
            b_advantages, b_returns, b_values = b_advantages.clone(), b_returns.clone(), b_values.clone()
            sum_pg = sum_v = sum_kl = sum_clip = torch.zeros((), device=device)
            num_updates = 0
            for epoch in range(cfg.update_epochs):
                permutation = torch.randperm(batch_size, generator=generator).to(device)
                epoch_kl = torch.zeros((), device=device)
                for start in range(0, batch_size, minibatch_size):
                    idx = permutation[start:start + minibatch_size]
                    mb_obs, mb_actions = b_obs[idx], b_actions[idx]
                    log_std = model.log_std
                    mean = model.actor_mean(mb_obs)
                    z = (mb_actions - mean) * torch.exp(-log_std)
                    new_logprob = -0.5 * z.pow(2).sum(1) - log_std.sum() - 0.5 * act_dim * log_2pi
                    log_ratio = new_logprob - b_logprob[idx]
                    ratio = log_ratio.exp()
                    mb_adv = b_advantages[idx]
                    if cfg.norm_adv:
                        mb_adv = (mb_adv - mb_adv.mean()) / (mb_adv.std() + 1e-8)
                    pg_loss = torch.max(-mb_adv * ratio,
                                        -mb_adv * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)).mean()
                    new_value = model.value(mb_obs)
                    if cfg.clip_vloss:
                        clipped = b_values[idx] + (new_value - b_values[idx]).clamp(-cfg.clip_coef, cfg.clip_coef)
                        v_loss = 0.5 * torch.max((new_value - b_returns[idx]).pow(2),
                                                 (clipped - b_returns[idx]).pow(2)).mean()
                    else:
                        v_loss = 0.5 * (new_value - b_returns[idx]).pow(2).mean()
                    # State-independent Gaussian: entropy = sum(log_std) + const.
                    entropy = log_std.sum() + 0.5 * act_dim * (1.0 + log_2pi)
                    loss = pg_loss - cfg.ent_coef * entropy + cfg.vf_coef * v_loss
                    if not torch.isfinite(loss):
                        raise NonFiniteError(f"train: the PPO loss became NaN/inf at step {global_step} "
                                             f"(policy {pg_loss.item()}, value {v_loss.item()})")
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    if cfg.max_grad_norm is not None:
                        nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm, foreach=True)
                    optimizer.step()
                    with torch.no_grad():
                        approx_kl = ((ratio - 1) - log_ratio).mean()
                        epoch_kl = approx_kl
                        sum_pg = sum_pg + pg_loss.detach()
                        sum_v = sum_v + v_loss.detach()
                        sum_kl = sum_kl + approx_kl
                        sum_clip = sum_clip + ((ratio - 1).abs() > cfg.clip_coef).float().mean()
                    num_updates += 1
                if cfg.target_kl is not None and epoch_kl.item() > cfg.target_kl:
                    break

            obs_np[0] = obs_np[T]  # the next rollout starts where this one ended
            update_end = time.perf_counter()
            wall_s = wall_offset + (update_end - start_time)

            # ---------------------------------------------------------------- logging
            ended_r = np.concatenate(ended_returns) if ended_returns else np.zeros(0)
            ended_l = np.concatenate(ended_lengths) if ended_lengths else np.zeros(0, np.int64)
            ended_s = np.concatenate(ended_success) if ended_success else np.zeros(0)
            with torch.no_grad():
                var_returns = b_returns.var()
                explained = 1.0 - (b_returns - b_values).var() / var_returns if var_returns > 0 else torch.tensor(float("nan"))
            row = {
                "step": global_step,
                "wall_s": round(wall_s, 4),
                "iteration": iteration,
                "episode_return": float(ended_r.mean()) if len(ended_r) else float("nan"),
                "episode_length": float(ended_l.mean()) if len(ended_l) else float("nan"),
                "success_rate": float(np.nanmean(ended_s)) if np.isfinite(ended_s).any() else float("nan"),
                "episodes": int(len(ended_r)),
                "sps": round(batch_size / max(wall_s - previous_wall_s, 1e-9), 1),
                "learning_rate": lr,
                "policy_loss": float(sum_pg / num_updates),
                "value_loss": float(sum_v / num_updates),
                "entropy": float(model.log_std.detach().sum() + 0.5 * act_dim * (1.0 + log_2pi)),
                "approx_kl": float(sum_kl / num_updates),
                "clipfrac": float(sum_clip / num_updates),
                "explained_variance": float(explained),
                # Cost per env step (summed over envs), microseconds: the env,
                # PPO's acting and advantage work, and the update.
                "env_us": 1e6 * env_seconds / batch_size,
                "act_us": 1e6 * (update_start - rollout_start - env_seconds) / batch_size,
                "update_us": 1e6 * (update_end - update_start) / batch_size,
            }
            stats = dict(row, episode_data={"return": ended_r, "length": ended_l, "success": ended_s})
            for callback in callbacks:
                if hasattr(callback, "on_iteration"):
                    extra = callback.on_iteration(stats)
                    if extra:
                        row.update(extra)
            if iteration % cfg.log_interval == 0:
                log.write(row)
            last_row = row
            previous_wall_s = wall_s
            if progress is not None:
                progress.update(min(global_step, cfg.total_steps) - progress.n)
                progress.set_postfix(sps=f"{row['sps']:.0f}", ret=f"{row['episode_return']:.1f}",
                                     success=f"{row['success_rate']:.2f}", refresh=False)

            # ---------------------------------------------------------------- checkpoints
            due_snapshots = [s for s in cfg.snapshot_steps if s <= global_step and s not in saved_snapshots]
            if due_snapshots or global_step - last_checkpoint_step >= cfg.checkpoint_interval_steps:
                saved_snapshots.update(due_snapshots)
                state = checkpoint_state(wall_s)
                save_checkpoint(state, latest_path)
                for s in due_snapshots:
                    save_checkpoint(state, out_dir / f"snapshot_{s}.pt")
                last_checkpoint_step = global_step
        save_checkpoint(checkpoint_state(wall_s), latest_path)
    except KeyboardInterrupt:
        # Keep the progress made so far; --resume continues from here.
        save_checkpoint(checkpoint_state(wall_s), latest_path)
        raise
    finally:
        if progress is not None:
            progress.close()
        log.close()
    if cfg.max_seconds is not None and wall_s >= cfg.max_seconds and global_step < cfg.total_steps:
        stopped_by = "seconds"
    return TrainResult(global_step=global_step, wall_s=wall_s, iterations=iteration, stopped_by=stopped_by,
                       last_stats=last_row, checkpoint=latest_path, metrics_csv=log.path)
