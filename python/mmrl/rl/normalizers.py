"""Running statistics and the observation normalizer, shared by training and acting.

``RunningMeanStd`` accumulates the mean and variance of a stream (observations, returns);
``ObsNormalizer`` holds one plus the frozen affine map a policy applies before its network.
Both save to and load from plain dicts of tensors (a weights-only checkpoint load reads them).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch

__all__ = ["RunningMeanStd", "ObsNormalizer"]


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
