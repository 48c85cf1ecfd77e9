# size: over 500 lines on purpose: PPOConfig documents each of its ~30 fields (~150 lines) and
# stays here beside the algorithm it tunes, as in cleanrl.
"""Proximal Policy Optimization for gymnasium 1.x vector envs.

Reads top to bottom like cleanrl's single file: the config, GAE, rollout collection, the
update, and ``train``'s short loop (collect a rollout, compute advantages, update, log,
checkpoint). The rest lives in modules of its own and is re-exported here: checkpoint files
and RNG capture in ``mmrl.rl.checkpoints``, the learner's state in
``mmrl.rl.training_state``, the metrics log and progress bar in ``mmrl.logs``, the
observation normalizer in ``mmrl.rl.normalizers``, the policy loader used by ``mmrl
eval``/``render`` in ``mmrl.rl.trained_policy``, the networks in ``mmrl.rl.networks``.

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
- Ctrl-C keeps the progress of every completed iteration: the learner's state
  (weights, optimizer, normalizers, step count, iteration, wall time, RNG) only
  changes between rollouts, Ctrl-C during that short stretch is held until the
  iteration is done, and the checkpoint written on Ctrl-C is the state as of the
  last completed iteration, the steps of an unfinished rollout discarded.
"""
from __future__ import annotations

import contextlib
import math
import os
import random
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Literal, Optional, Sequence

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from ..io import remove_stale_temps
from .checkpoints import CheckpointError, capture_rng_state, load_checkpoint, save_checkpoint, save_due_checkpoints
from ..logs import MetricsLogger, ProgressBar
from .normalizers import ObsNormalizer, RunningMeanStd
from .trained_policy import NonFiniteError, Policy, load_policy, resolve_device
from .training_state import TrainingState

__all__ = [
    "PPOConfig", "TrainResult", "train", "load_policy", "Policy", "compute_gae", "successor_values",
    "CheckpointError", "NonFiniteError", "save_checkpoint", "load_checkpoint",
]

LOG_2PI = math.log(2 * math.pi)

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

    network: str = "default"
    """The actor-critic the task's ``policy_factory`` builds: "default", or a name the task
    knows (the obstacles task: "cnn", the paper's, and "mlp"). Ignored when ``ppo.train`` gets a
    ``policy_factory`` of its own."""

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

    hidden: tuple[int, ...] = (32, 32)
    """Hidden layer sizes of the default network (``PlaneActorCritic``, tanh; tasks with their
    own network ignore it). A policy conditioned on many requests (docs/styles.md) may want more."""

    snapshot_steps: tuple[int, ...] = ()
    """Also keep ``snapshot_<N>.pt`` the first time the global step reaches each
    N, e.g. (20_000, 100_000, 533_000, 1_000_000) for the paper's Figure 4."""

    def __post_init__(self) -> None:
        if self.num_steps < 1 or self.update_epochs < 1 or self.num_minibatches < 1:
            raise ValueError("PPOConfig: num_steps, update_epochs and num_minibatches must be >= 1")
        if self.reward_norm not in ("scale", "value", "none"):
            raise ValueError(f"PPOConfig: reward_norm must be 'scale', 'value' or 'none', got {self.reward_norm!r}")
        self.snapshot_steps = tuple(int(s) for s in self.snapshot_steps)
        self.hidden = tuple(int(s) for s in self.hidden)
        if not self.hidden or min(self.hidden) < 1:
            raise ValueError(f"PPOConfig: hidden must be one or more positive layer sizes, got {self.hidden}")
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


# ----------------------------------------------------------------------------- setup

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


def _make_learner(envs: gym.vector.VectorEnv, cfg: PPOConfig, policy_factory: Optional[Callable[[int, int], nn.Module]],
                  callbacks: list) -> TrainingState:
    """Seed everything, then build the network, optimizer and normalizers for ``envs``."""
    obs_dim, act_dim = _check_env(envs)
    action_center = action_half = None
    space = envs.single_action_space
    if cfg.rescale_actions and np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)):
        action_center = ((space.high + space.low) / 2).astype(np.float32)
        action_half = ((space.high - space.low) / 2).astype(np.float32)
    device = resolve_device(cfg.device)
    if cfg.torch_threads > 0:
        torch.set_num_threads(cfg.torch_threads)

    # Seeding. PPO's own sampling uses a CPU generator so devices agree.
    random.seed(cfg.seed)
    np.random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    generator = torch.Generator().manual_seed(cfg.seed)

    if policy_factory is None:
        from .networks import PlaneActorCritic
        model = PlaneActorCritic(obs_dim, act_dim, hidden=cfg.hidden, init_log_std=cfg.init_log_std).to(device)
    else:
        model = policy_factory(obs_dim, act_dim).to(device)
    # The fused Adam kernel (CPU and CUDA, torch >= 2.4) is ~7x cheaper per step
    # than the default for-loop on these tiny networks.
    try:
        optimizer = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5, fused=True)
    except (RuntimeError, TypeError):
        optimizer = torch.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5)
    return TrainingState(cfg=cfg, model=model, optimizer=optimizer,
                         obs_normalizer=ObsNormalizer(obs_dim, cfg.obs_norm, cfg.obs_norm_exclude, cfg.obs_clip, device),
                         return_rms=RunningMeanStd(), running_return=np.zeros(envs.num_envs, np.float64),
                         generator=generator, device=device, action_center=action_center, action_half=action_half,
                         callbacks=callbacks)


# ----------------------------------------------------------------------------- rollout collection

class RolloutStorage:
    """The CPU buffers of one rollout of T steps of N envs. Env results are written
    through numpy views, one copy each; the batch moves to the device once per update.
    ``obs[t]`` is the obs acted on at step t; ``obs[T]`` the one after the last step,
    where the next rollout starts."""

    def __init__(self, num_steps: int, num_envs: int, obs_dim: int, act_dim: int):
        self.obs = torch.zeros(num_steps + 1, num_envs, obs_dim)
        self.obs_np = self.obs.numpy()
        self.actions = torch.zeros(num_steps, num_envs, act_dim)  # in the policy's units (before rescaling)
        self.rewards = np.zeros((num_steps, num_envs), np.float64)
        self.terminated = np.zeros((num_steps, num_envs), bool)
        self.truncated = np.zeros((num_steps, num_envs), bool)
        # Per env, the episode so far; carried across rollouts.
        self.episode_return = np.zeros(num_envs, np.float64)
        self.episode_length = np.zeros(num_envs, np.int64)


@dataclass
class Rollout:
    """What a rollout produced besides the storage."""

    noise: torch.Tensor
    """(T, N, act_dim) standard normal draws on the device: action = mean + std * noise."""
    final_obs: list
    """(t, env indices, their final obs) for each step where episodes were truncated."""
    ended_returns: np.ndarray
    ended_lengths: np.ndarray
    ended_success: np.ndarray
    """Of the episodes that ended, in order; success is NaN where the env gave no flag."""
    env_seconds: float
    """Wall time spent in ``envs.step``."""


def _final_obs_rows(infos: dict, envs_idx: np.ndarray) -> np.ndarray:
    if "final_obs" not in infos:
        raise ValueError("train: an episode was truncated but infos has no 'final_obs' (SAME_STEP contract)")
    final_obs = infos["final_obs"]
    if final_obs.dtype == object:  # gymnasium's SyncVectorEnv stores one array per env
        return np.stack([np.asarray(final_obs[i], np.float32) for i in envs_idx])
    return np.asarray(final_obs[envs_idx], np.float32)


def _end_episodes(storage: RolloutStorage, t: int, terminated: np.ndarray, truncated: np.ndarray, infos: dict,
                  ended: tuple[list, list, list], final_obs: list) -> None:
    """Record the episodes that ended at step t and restart their accumulators."""
    ended_idx = np.flatnonzero(terminated | truncated)
    returns, lengths, success = ended
    returns.append(storage.episode_return[ended_idx].copy())
    lengths.append(storage.episode_length[ended_idx].copy())
    if "success" in infos:
        mask = infos.get("_success", np.ones(len(terminated), bool))[ended_idx]
        success.append(np.where(mask, infos["success"][ended_idx].astype(np.float64), np.nan))
    else:
        success.append(np.full(len(ended_idx), np.nan))
    storage.episode_return[ended_idx] = 0.0
    storage.episode_length[ended_idx] = 0
    cut = np.flatnonzero(truncated & ~terminated)
    if len(cut):
        final_obs.append((t, cut, _final_obs_rows(infos, cut)))


def collect_rollout(envs: gym.vector.VectorEnv, learner: TrainingState, storage: RolloutStorage,
                    noise: torch.Tensor) -> Rollout:
    """Act ``len(noise)`` steps in ``envs`` from ``storage.obs[0]`` with the frozen normalizer,
    filling ``storage``. Changes nothing in ``learner``."""
    model, normalizer, device = learner.model, learner.obs_normalizer, learner.device
    step = learner.global_step  # for error messages
    final_obs: list = []
    ended: tuple[list, list, list] = ([], [], [])
    env_seconds = 0.0
    # mmrl's vector envs write observations straight into the rollout (step_into) and refuse
    # non-finite actions in C++: one check, no copy. Other envs: step() and the check here.
    step_into = callable(getattr(envs, "step_into", None))
    with torch.inference_mode():
        std = model.log_std.exp().to(device)
        noise_dev = noise.to(device)
        for t in range(noise.shape[0]):
            mean = model.actor_mean(normalizer(storage.obs[t].to(device, non_blocking=True)))
            action = torch.addcmul(mean, std, noise_dev[t])
            action_np = action.numpy() if device.type == "cpu" else action.cpu().numpy()
            storage.actions[t] = torch.from_numpy(action_np) if device.type != "cpu" else action
            if not step_into and not np.isfinite(action_np).all():  # (mmrl's envs check in C++)
                raise NonFiniteError(f"train: the policy produced NaN/inf actions at step {step}")
            env_start = time.perf_counter()
            if learner.action_center is not None:
                action_np = learner.action_center + learner.action_half * action_np
            if step_into:  # the observations go straight into the rollout's row
                try:
                    obs, reward, terminated, truncated, infos = envs.step_into(action_np, storage.obs_np[t + 1])
                except ValueError as e:
                    if not np.isfinite(action_np).all():
                        raise NonFiniteError(f"train: the policy produced NaN/inf actions at step {step}") from e
                    raise
            else:
                obs, reward, terminated, truncated, infos = envs.step(action_np)
                storage.obs_np[t + 1] = obs
            env_seconds += time.perf_counter() - env_start
            if not np.isfinite(obs).all() or not np.isfinite(reward).all():
                raise NonFiniteError(f"train: the env returned NaN/inf observations or rewards at step {step}")
            storage.rewards[t] = reward
            storage.terminated[t] = terminated
            storage.truncated[t] = truncated
            storage.episode_return += reward
            storage.episode_length += 1
            step += envs.num_envs
            if (terminated | truncated).any():
                _end_episodes(storage, t, terminated, truncated, infos, ended, final_obs)
    returns, lengths, success = ended
    return Rollout(noise=noise_dev, final_obs=final_obs,
                   ended_returns=np.concatenate(returns) if returns else np.zeros(0),
                   ended_lengths=np.concatenate(lengths) if lengths else np.zeros(0, np.int64),
                   ended_success=np.concatenate(success) if success else np.zeros(0),
                   env_seconds=env_seconds)


# ----------------------------------------------------------------------------- advantages

@dataclass
class Batch:
    """A rollout flattened to T * N rows for the update, on the device."""

    obs: torch.Tensor  # normalized as when acting
    actions: torch.Tensor
    logprob: torch.Tensor  # of the actions under the acting policy
    advantages: torch.Tensor
    returns: torch.Tensor  # value targets, in the value net's units
    values: torch.Tensor  # the value net's predictions when acting, same units


def compute_batch(learner: TrainingState, storage: RolloutStorage, rollout: Rollout) -> Batch:
    """Values of all observations in one batched call, successor values, reward
    normalization and GAE; updates the return statistics of ``cfg.reward_norm``."""
    cfg, model, normalizer, device = learner.cfg, learner.model, learner.obs_normalizer, learner.device
    T, num_envs, act_dim = storage.actions.shape
    batch_size = T * num_envs
    with torch.inference_mode():
        all_obs = normalizer(storage.obs.to(device).reshape(batch_size + num_envs, -1))
        values = model.value(all_obs).reshape(T + 1, num_envs).double().cpu().numpy()
        final_values = np.zeros(0)
        if rollout.final_obs:
            stacked = torch.from_numpy(np.concatenate([rows for _, _, rows in rollout.final_obs])).to(device)
            final_values = model.value(normalizer(stacked)).double().cpu().numpy()
        rms = learner.return_rms
        if cfg.reward_norm == "value":  # the net predicts standardized returns
            values = values * math.sqrt(float(rms.var) + 1e-8) + float(rms.mean)
            final_values = final_values * math.sqrt(float(rms.var) + 1e-8) + float(rms.mean)
        next_values = successor_values(values, storage.terminated, [(t, cut) for t, cut, _ in rollout.final_obs],
                                       final_values)
        episode_ends = storage.terminated | storage.truncated
        rewards = storage.rewards
        if cfg.reward_norm == "scale":
            rewards = scale_rewards(storage.rewards, episode_ends, learner.running_return, rms, cfg.gamma,
                                    cfg.reward_clip)
        advantages, returns = compute_gae(rewards, values[:-1], next_values, episode_ends, cfg.gamma,
                                          cfg.gae_lambda)
        old_values = values[:-1]
        if cfg.reward_norm == "value":
            rms.update(returns.reshape(-1))
            value_scale = math.sqrt(float(rms.var) + 1e-8)
            returns = (returns - float(rms.mean)) / value_scale
            old_values = (values[:-1] - float(rms.mean)) / value_scale

        noise = rollout.noise.reshape(batch_size, act_dim)
        logprob = -0.5 * noise.pow(2).sum(1) - model.log_std.sum() - 0.5 * act_dim * LOG_2PI
        tensors = (all_obs[:batch_size], storage.actions.reshape(batch_size, act_dim).to(device), logprob,
                   *(torch.from_numpy(a.reshape(-1).astype(np.float32)).to(device)
                     for a in (advantages, returns, old_values)))
    # Clone out of inference mode so autograd may use them.
    return Batch(*(tensor.clone() for tensor in tensors))


# ----------------------------------------------------------------------------- update

def _minibatch_loss(cfg: PPOConfig, model: nn.Module, batch: Batch, idx: torch.Tensor) -> tuple:
    """The clipped PPO loss of one minibatch; returns (loss, pg_loss, v_loss, ratio, log_ratio)."""
    act_dim = batch.actions.shape[1]
    log_std = model.log_std
    mb_obs = batch.obs[idx]
    mean = model.actor_mean(mb_obs)
    z = (batch.actions[idx] - mean) * torch.exp(-log_std)
    new_logprob = -0.5 * z.pow(2).sum(1) - log_std.sum() - 0.5 * act_dim * LOG_2PI
    log_ratio = new_logprob - batch.logprob[idx]
    ratio = log_ratio.exp()
    mb_adv = batch.advantages[idx]
    if cfg.norm_adv:
        mb_adv = (mb_adv - mb_adv.mean()) / (mb_adv.std() + 1e-8)
    pg_loss = torch.max(-mb_adv * ratio, -mb_adv * ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef)).mean()
    new_value = model.value(mb_obs)
    if cfg.clip_vloss:
        clipped = batch.values[idx] + (new_value - batch.values[idx]).clamp(-cfg.clip_coef, cfg.clip_coef)
        v_loss = 0.5 * torch.max((new_value - batch.returns[idx]).pow(2),
                                 (clipped - batch.returns[idx]).pow(2)).mean()
    else:
        v_loss = 0.5 * (new_value - batch.returns[idx]).pow(2).mean()
    # State-independent Gaussian: entropy = sum(log_std) + const.
    entropy = log_std.sum() + 0.5 * act_dim * (1.0 + LOG_2PI)
    loss = pg_loss - cfg.ent_coef * entropy + cfg.vf_coef * v_loss
    return loss, pg_loss, v_loss, ratio, log_ratio


def ppo_update(learner: TrainingState, batch: Batch) -> dict:
    """``cfg.update_epochs`` passes of minibatch Adam steps over ``batch`` (stopping early
    past ``cfg.target_kl``); returns the mean losses, KL and clip fraction over the steps."""
    cfg, model, optimizer, device = learner.cfg, learner.model, learner.optimizer, learner.device
    batch_size = batch.obs.shape[0]
    minibatch_size = max(1, batch_size // cfg.num_minibatches)
    sum_pg = sum_v = sum_kl = sum_clip = torch.zeros((), device=device)
    num_updates = 0
    for epoch in range(cfg.update_epochs):
        permutation = torch.randperm(batch_size, generator=learner.generator).to(device)
        epoch_kl = torch.zeros((), device=device)
        for start in range(0, batch_size, minibatch_size):
            idx = permutation[start:start + minibatch_size]
            loss, pg_loss, v_loss, ratio, log_ratio = _minibatch_loss(cfg, model, batch, idx)
            if not torch.isfinite(loss):
                raise NonFiniteError(f"train: the PPO loss became NaN/inf at step {learner.global_step + batch_size} "
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
    return {"policy_loss": float(sum_pg / num_updates), "value_loss": float(sum_v / num_updates),
            "approx_kl": float(sum_kl / num_updates), "clipfrac": float(sum_clip / num_updates)}


# ----------------------------------------------------------------------------- training loop

def _metrics_row(learner: TrainingState, rollout: Rollout, batch: Batch, losses: dict, lr: float,
                 previous_wall_s: float, times: tuple[float, float, float]) -> dict:
    """The iteration's CSV/TensorBoard row (``MetricsLogger.BASE_COLUMNS``)."""
    rollout_start, update_start, update_end = times
    batch_size, act_dim = batch.actions.shape
    ended_r, ended_l, ended_s = rollout.ended_returns, rollout.ended_lengths, rollout.ended_success
    with torch.no_grad():
        var_returns = batch.returns.var()
        explained = 1.0 - (batch.returns - batch.values).var() / var_returns if var_returns > 0 else torch.tensor(float("nan"))
    return {
        "step": learner.global_step,
        "wall_s": round(learner.wall_s, 4),
        "iteration": learner.iteration,
        "episode_return": float(ended_r.mean()) if len(ended_r) else float("nan"),
        "episode_length": float(ended_l.mean()) if len(ended_l) else float("nan"),
        "success_rate": float(np.nanmean(ended_s)) if np.isfinite(ended_s).any() else float("nan"),
        "episodes": int(len(ended_r)),
        "sps": round(batch_size / max(learner.wall_s - previous_wall_s, 1e-9), 1),
        "learning_rate": lr,
        "policy_loss": losses["policy_loss"],
        "value_loss": losses["value_loss"],
        "entropy": float(learner.model.log_std.detach().sum() + 0.5 * act_dim * (1.0 + LOG_2PI)),
        "approx_kl": losses["approx_kl"],
        "clipfrac": losses["clipfrac"],
        "explained_variance": float(explained),
        # Cost per env step (summed over envs), microseconds: the env,
        # PPO's acting and advantage work, and the update.
        "env_us": 1e6 * rollout.env_seconds / batch_size,
        "act_us": 1e6 * (update_start - rollout_start - rollout.env_seconds) / batch_size,
        "update_us": 1e6 * (update_end - update_start) / batch_size,
    }


def _run_callbacks(callbacks: list, row: dict, rollout: Rollout) -> None:
    """Call each ``on_iteration(stats)``; the scalars they return become extra columns of ``row``."""
    stats = dict(row, episode_data={"return": rollout.ended_returns, "length": rollout.ended_lengths,
                                    "success": rollout.ended_success})
    for callback in callbacks:
        if hasattr(callback, "on_iteration"):
            extra = callback.on_iteration(stats)
            if extra:
                row.update(extra)


@contextlib.contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) until the block ends, then raise KeyboardInterrupt, so an update
    and its bookkeeping are never left half done. A second Ctrl-C interrupts at once. Only
    with Python's default handler in the main thread; otherwise the block runs unguarded."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    received = []

    def hold(signum: int, frame: Any) -> None:
        received.append(signum)
        signal.signal(signal.SIGINT, signal.default_int_handler)

    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if received:
        raise KeyboardInterrupt


def _learn(learner: TrainingState, storage: RolloutStorage, rollout: Rollout, lr: float, rollout_start: float,
           wall_clock: Callable[[], float]) -> dict:
    """Everything after a rollout that changes the learner: advantages, observation
    statistics, the update, the counters and the callbacks. Returns the metrics row."""
    cfg = learner.cfg
    batch = compute_batch(learner, storage, rollout)
    if cfg.obs_norm:  # update the observation statistics from this rollout, for the next one
        learner.obs_normalizer.rms.update(storage.obs_np[1:].reshape(batch.obs.shape[0], -1))
        learner.obs_normalizer.refresh()
    update_start = time.perf_counter()
    losses = ppo_update(learner, batch)
    storage.obs_np[0] = storage.obs_np[-1]  # the next rollout starts where this one ended
    update_end = time.perf_counter()
    previous_wall_s = learner.wall_s
    learner.global_step += batch.obs.shape[0]
    learner.iteration += 1
    learner.wall_s = wall_clock()
    row = _metrics_row(learner, rollout, batch, losses, lr, previous_wall_s, (rollout_start, update_start, update_end))
    _run_callbacks(learner.callbacks, row, rollout)
    return row


def train(envs: gym.vector.VectorEnv, cfg: PPOConfig, out_dir: str | os.PathLike, *,
          policy_factory: Optional[Callable[[int, int], nn.Module]] = None, resume: bool = False,
          callbacks: Sequence[Any] | None = None) -> TrainResult:
    """Train a Gaussian policy with PPO on ``envs``; write metrics and checkpoints to ``out_dir``.

    ``policy_factory(obs_dim, act_dim)`` builds the actor-critic (default: the
    paper's ``PlaneActorCritic``); see ``mmrl.rl.networks`` for the interface, and register
    the class there (``register_network``) so ``load_policy`` can rebuild it.
    ``resume=True`` continues from ``out_dir/latest.pt``: model, optimizer,
    normalizers, step, wall time, RNG and callback state. The envs are reset
    (their state is not checkpointed) with seed ``cfg.seed + global_step``.
    ``callbacks``: objects with any of ``on_iteration(stats) -> dict | None``
    (extra scalar columns for CSV/TensorBoard), ``state_dict()`` and
    ``load_state_dict(state)`` (stored in checkpoints under their index).
    ``stats`` holds the iteration's scalars plus ``stats["episode_data"]``, a dict
    of arrays "return", "length", "success" for the episodes that ended.
    On Ctrl-C, latest.pt holds the state as of the last completed iteration.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    latest_path = out_dir / "latest.pt"
    if not resume and latest_path.exists():
        raise FileExistsError(f"{out_dir} already holds a run ({latest_path}); pass resume=True or use a new directory")
    # A run killed while writing leaves hidden temp files (mmrl.io); a run directory has one writer.
    for name in ("latest.pt", "metrics.csv", "config.json", *(f"snapshot_{s}.pt" for s in cfg.snapshot_steps)):
        remove_stale_temps(out_dir / name)
    learner = _make_learner(envs, cfg, policy_factory, list(callbacks or []))
    if resume:
        learner.load(latest_path)
    storage = RolloutStorage(cfg.num_steps, envs.num_envs, *_check_env(envs))
    storage.obs_np[0], _ = envs.reset(seed=cfg.seed + learner.global_step)
    log = MetricsLogger(out_dir, learner.global_step if resume else None, cfg.tensorboard)
    progress = ProgressBar(cfg.total_steps, cfg.max_seconds, learner.global_step, learner.wall_s) if cfg.progress else None
    last_row: dict = {}
    last_saved_step = learner.global_step
    start_time, wall_offset = time.perf_counter(), learner.wall_s
    rng: Optional[dict] = capture_rng_state(learner.generator)  # as of the last completed iteration
    try:
        while learner.global_step < cfg.total_steps:
            if cfg.max_seconds is not None and learner.wall_s >= cfg.max_seconds:
                break
            lr = cfg.learning_rate * (1.0 - learner.global_step / cfg.total_steps if cfg.anneal_lr else 1.0)
            for group in learner.optimizer.param_groups:
                group["lr"] = lr
            rollout_start = time.perf_counter()
            noise = torch.randn(*storage.actions.shape, generator=learner.generator)
            rollout = collect_rollout(envs, learner, storage, noise)  # changes nothing in the learner
            with _ctrl_c_held():
                rng = None  # the learner is changing: a (second) Ctrl-C now saves nothing
                last_row = _learn(learner, storage, rollout, lr, rollout_start,
                                  lambda: wall_offset + (time.perf_counter() - start_time))
                if learner.iteration % cfg.log_interval == 0:
                    log.write(last_row)
                if progress is not None:
                    progress.update(learner.global_step, learner.wall_s, last_row)
                rng = capture_rng_state(learner.generator)
                last_saved_step = save_due_checkpoints(learner, rng, out_dir, last_saved_step)
        save_checkpoint(learner.checkpoint(rng), latest_path)
    except KeyboardInterrupt as e:
        # Keep the progress of every completed iteration; --resume continues from there.
        if rng is not None:
            save_checkpoint(learner.checkpoint(rng), latest_path)
            e.saved = f"saved step {learner.global_step:,} to {latest_path}; continue with: mmrl train --resume {out_dir}"
        elif latest_path.exists():
            e.saved = f"{latest_path} holds the last saved checkpoint; continue with: mmrl train --resume {out_dir}"
        raise
    finally:
        if progress is not None:
            progress.close()
        log.close()
    stopped_by = "steps"
    if cfg.max_seconds is not None and learner.wall_s >= cfg.max_seconds and learner.global_step < cfg.total_steps:
        stopped_by = "seconds"
    return TrainResult(global_step=learner.global_step, wall_s=learner.wall_s, iterations=learner.iteration,
                       stopped_by=stopped_by, last_stats=last_row, checkpoint=latest_path, metrics_csv=log.path)
