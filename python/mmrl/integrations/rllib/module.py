"""The mmrl actor-critic networks as an RLlib RLModule.

RLlib trains the very network class our PPO trains (``mmrl.rl.networks``: the paper's 32 x 32
MLP for the plane, its CNN for the obstacles), so a run trained by RLlib exports to the same
``latest.pt`` that ``mmrl eval``, ``render``, ``play`` and ``export`` load. The action
distribution is RLlib's diagonal Gaussian over [mean, log_std], with the network's free
log-std parameter (RLlib's default network makes the log-std an output instead).
"""
from __future__ import annotations

import functools
from typing import Any, Dict, Optional

import numpy as np
import torch
from ray.rllib.connectors.env_to_module import MeanStdFilter
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
from ray.rllib.core.rl_module.torch import TorchRLModule

from ...rl.networks import network_class


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


class RangeMeanStdFilter(MeanStdFilter):
    """RLlib's MeanStdFilter, leaving the observation entries [a, b) of ``exclude`` as they
    are (the obstacles' binary sensor maps, which our trainer does not normalize either)."""

    def __init__(self, *, exclude: Optional[tuple] = None, **kwargs):
        super().__init__(**kwargs)
        self.exclude = None if exclude is None else (int(exclude[0]), int(exclude[1]))

    def __call__(self, *, rl_module, batch, episodes, **kwargs):
        if self.exclude is None:
            return super().__call__(rl_module=rl_module, batch=batch, episodes=episodes, **kwargs)
        a, b = self.exclude
        raw = [np.array(e.get_observations(indices=-1)[a:b]) for e in self.single_agent_episode_iterator(episodes)]
        out = super().__call__(rl_module=rl_module, batch=batch, episodes=episodes, **kwargs)
        for e, kept in zip(self.single_agent_episode_iterator(episodes), raw):
            obs = np.array(e.get_observations(indices=-1))
            obs[a:b] = kept
            e.set_observations(at_indices=-1, new_data=obs)
        return out


def range_mean_std_filter(exclude: Optional[tuple]):
    """A connector factory for ``config.env_runners(env_to_module_connector=...)``."""
    return functools.partial(_make_filter, exclude)


def _make_filter(exclude, env=None, spaces=None, device=None):
    return RangeMeanStdFilter(exclude=exclude)
