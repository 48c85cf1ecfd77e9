"""A trained policy for evaluation and rendering, and the observation normalizer it applies.

(``mmrl.rl.policies`` holds the scripted joystick policies; this module is the learned one.)

``load_policy(path)`` rebuilds what ``mmrl.rl.ppo.train`` saved: the network (from the registry
in ``mmrl.rl.networks``), the frozen observation normalization and the action rescaling.
``RunningMeanStd`` and ``ObsNormalizer`` live here because acting needs them as much as
training does; ``mmrl.rl.ppo`` uses the same classes.
"""
from __future__ import annotations

import os
from typing import Optional

import numpy as np
import torch
from torch import nn

from .checkpoints import CheckpointError, build_network, load_checkpoint

__all__ = ["Policy", "load_policy", "NonFiniteError", "RunningMeanStd", "ObsNormalizer", "resolve_device"]


class NonFiniteError(RuntimeError):
    """NaN or inf in observations, actions, rewards or the loss."""


def resolve_device(device: str) -> torch.device:
    """"auto" = CUDA if available, else CPU; or any torch device string."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


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
    """Rebuild the policy saved in a checkpoint written by ``mmrl.rl.ppo.train``.

    Raises ``CheckpointError`` naming the file if it is missing, corrupt, foreign, or names
    a network that is not registered (see ``mmrl.rl.networks.register_network``).
    """
    device_t = resolve_device(device)
    state = load_checkpoint(path)
    model = build_network(state, path)
    try:
        model = model.to(device_t)
        model.load_state_dict(state["model"])
    except Exception as error:
        raise CheckpointError(f"{path}: cannot rebuild the network: {error}") from error
    # Any shape of these entries can come out of a weights-only load: a malformed one is a
    # corrupt checkpoint, not a KeyError (found by tests/fuzz/fuzz_python.py checkpoint).
    try:
        obs_dim = state["obs_normalizer"]["rms"]["mean"].shape[0]
        normalizer = ObsNormalizer(obs_dim, True, None, 10.0, device_t)
        normalizer.load_state_dict(state["obs_normalizer"])
        center, half = state.get("action_center"), state.get("action_half")
        return Policy(model, normalizer, device_t,
                      None if center is None else np.asarray(center, np.float32),
                      None if half is None else np.asarray(half, np.float32))
    except Exception as error:
        raise CheckpointError(f"{path}: corrupt observation normalizer or action scaling: {error!r}") from error
