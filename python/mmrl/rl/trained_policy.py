"""A trained policy for evaluation and rendering.

(``mmrl.rl.policies`` holds the scripted joystick policies; this module is the learned one.)

``load_policy(path)`` rebuilds what ``mmrl.rl.ppo.train`` saved: the network (from the registry
in ``mmrl.rl.networks``), the frozen observation normalization and the action rescaling.
The normalizer it applies, ``ObsNormalizer`` (with ``RunningMeanStd``), lives in
:mod:`mmrl.rl.normalizers` (acting needs it as much as training does) and is re-exported here.
"""
from __future__ import annotations

import os
from typing import Optional

import numpy as np
import torch
from torch import nn

from .checkpoints import CheckpointError, build_network, load_checkpoint
from .normalizers import ObsNormalizer, RunningMeanStd

__all__ = ["Policy", "load_policy", "NonFiniteError", "RunningMeanStd", "ObsNormalizer", "resolve_device"]


class NonFiniteError(RuntimeError):
    """NaN or inf in observations, actions, rewards or the loss."""


def resolve_device(device: str) -> torch.device:
    """"auto" = CUDA if available, else CPU; or any torch device string."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


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
