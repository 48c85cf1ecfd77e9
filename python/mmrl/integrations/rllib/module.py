"""The mmrl actor-critic networks as an RLlib RLModule.

RLlib trains the very network class our PPO trains (``mmrl.networks``: the paper's 32 x 32
MLP for the plane, its CNN for the obstacles), so a run trained by RLlib exports to the same
``latest.pt`` that ``mmrl eval``, ``render``, ``play`` and ``export`` load. The action
distribution is RLlib's diagonal Gaussian over [mean, log_std], with the network's free
log-std parameter (RLlib's default network makes the log-std an output instead).
"""
from __future__ import annotations

from typing import Any, Dict, Optional

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
from ray.rllib.core.rl_module.torch import TorchRLModule

from ...networks import network_class


class MMRLTorchModule(TorchRLModule, ValueFunctionAPI):
    """``model_config``: ``{"model_class": registered network name, "model_kwargs": {...}}``."""

    def setup(self):
        cls = network_class(self.model_config["model_class"])
        self.net = cls(**self.model_config.get("model_kwargs", {}))

    def _dist_inputs(self, obs: torch.Tensor) -> torch.Tensor:
        mean = self.net.actor_mean(obs)
        return torch.cat([mean, self.net.log_std.expand_as(mean)], dim=-1)

    def _forward(self, batch: Dict[str, Any], **kwargs) -> Dict[str, Any]:
        return {Columns.ACTION_DIST_INPUTS: self._dist_inputs(batch[Columns.OBS])}

    def compute_values(self, batch: Dict[str, Any], embeddings: Optional[Any] = None) -> torch.Tensor:
        return self.net.value(batch[Columns.OBS])
