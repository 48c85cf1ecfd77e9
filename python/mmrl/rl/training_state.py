"""What ``mmrl.rl.ppo.train`` learns and counts: :class:`TrainingState`, the object a checkpoint
is written from and read back into.

The state sits beside, not inside, :mod:`mmrl.rl.checkpoints`: the checkpoint file format needs
neither the normalizers nor the trainer, and the trained-policy loader needs the file format
only, so the imports run one way (``ppo -> training_state -> checkpoints, normalizers``).
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
import torch
from torch import nn

from .checkpoints import CheckpointError, load_checkpoint, restore_rng_state
from .networks import network_name
from .normalizers import ObsNormalizer, RunningMeanStd

__all__ = ["TrainingState"]


@dataclass
class TrainingState:
    """What ``mmrl.rl.ppo.train`` learns and counts: what a checkpoint holds, plus the run's
    device and discounted-return accumulator (not saved: the envs restart on resume).

    ``train`` changes it only after a rollout, so between iterations it is consistent.
    """

    cfg: Any  # mmrl.rl.ppo.PPOConfig
    model: nn.Module
    optimizer: torch.optim.Optimizer
    obs_normalizer: ObsNormalizer
    return_rms: RunningMeanStd  # discounted returns ("scale") or value targets ("value")
    running_return: np.ndarray  # (num_envs,) discounted return so far, for "scale"
    generator: torch.Generator  # PPO's own sampling: action noise, minibatch order
    device: torch.device
    action_center: Optional[np.ndarray]  # env action = center + half * policy action, if rescaled
    action_half: Optional[np.ndarray]
    callbacks: list
    global_step: int = 0  # env steps summed over envs
    iteration: int = 0
    wall_s: float = 0.0  # training wall time in seconds, summed over resumes
    snapshots: set = field(default_factory=set)  # the snapshot_steps already saved

    def checkpoint(self, rng: dict) -> dict:
        """The dict ``save_checkpoint`` writes; ``rng`` from ``capture_rng_state(self.generator)``."""
        return {
            "model": self.model.state_dict(), "model_class": network_name(self.model),
            "model_kwargs": getattr(self.model, "init_kwargs", {}),
            "optimizer": self.optimizer.state_dict(), "obs_normalizer": self.obs_normalizer.state_dict(),
            "return_rms": self.return_rms.state_dict(), "global_step": self.global_step, "wall_s": self.wall_s,
            "iteration": self.iteration, "snapshots": sorted(self.snapshots), "rng": rng,
            "config": dataclasses.asdict(self.cfg),
            "action_center": None if self.action_center is None else self.action_center.tolist(),
            "action_half": None if self.action_half is None else self.action_half.tolist(),
            "callbacks": {i: cb.state_dict() for i, cb in enumerate(self.callbacks) if hasattr(cb, "state_dict")},
        }

    def load(self, path: str | os.PathLike) -> None:
        """Continue from a checkpoint ``train`` wrote (RNG states and callbacks included)."""
        state = load_checkpoint(path)  # on the CPU: RNG states must stay there
        try:
            self.model.load_state_dict(state["model"])
            self.optimizer.load_state_dict(state["optimizer"])
        except Exception as error:
            raise CheckpointError(f"{path}: does not fit this network/config: {error}") from error
        self.obs_normalizer.load_state_dict(state["obs_normalizer"])
        self.return_rms.load_state_dict(state["return_rms"])
        self.global_step, self.wall_s, self.iteration = state["global_step"], state["wall_s"], state["iteration"]
        self.snapshots = set(state["snapshots"])
        restore_rng_state(state["rng"], self.generator)
        for i, callback in enumerate(self.callbacks):
            if hasattr(callback, "load_state_dict") and i in state["callbacks"]:
                callback.load_state_dict(state["callbacks"][i])
