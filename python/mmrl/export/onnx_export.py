"""A trained policy as one ONNX graph, for engines with their own inference (Unity Sentis,
Unreal NNE, onnxruntime).

The graph maps the raw observation to the env's action with everything inside, so an engine
needs nothing else:

    input  ``obs``            (B, obs_dim) float32: the task's raw observation
    output ``action``         (B, 12) float32: ``Policy.act(obs)``, the deterministic action
                              (the observation normalization, the network's mean and the
                              action rescaling of ``mmrl.load_policy``)
    output ``clipped_action`` (B, 12) float32: ``action`` clipped to the env's action box
                              (mean +- action_limit_std * std of the database's trajectory
                              features): what the matcher receives as the query's trajectory half

Export uses torch's TorchScript exporter (``dynamo=False``): it needs only ``onnx``, where the
dynamo exporter of torch 2.x also needs ``onnxscript``. Checking needs ``onnxruntime``; both
are the ``mmrl[onnx]`` extra.
"""
from __future__ import annotations

import io
import os
import warnings
from typing import Optional

import numpy as np

from ..errors import InputError, require_extra
from ..io import atomic_write_bytes

__all__ = ["OPSET", "policy_graph_module", "export_onnx", "check_onnx"]

#: The ONNX opset written: 17 is read by onnxruntime >= 1.14, Unity Sentis and Unreal NNE.
OPSET = 17


def policy_graph_module(policy, action_low: Optional[np.ndarray] = None, action_high: Optional[np.ndarray] = None):
    """A torch module ``obs -> (action, clipped_action)`` equal to ``policy.act`` (deterministic).

    ``policy``: an :class:`mmrl.rl.trained_policy.Policy`; ``action_low``/``action_high``: the
    env's action box (12 each; None: no clipping, ``clipped_action`` equals ``action``).
    """
    import torch
    from torch import nn

    norm = policy.obs_normalizer
    obs_dim = int(norm.scale.shape[0])
    act_dim = int(policy.model.log_std.shape[0])

    def const(values, fill):
        v = np.full(act_dim, fill, np.float32) if values is None else np.asarray(values, np.float32)
        return torch.as_tensor(v.reshape(act_dim).copy())

    class PolicyGraph(nn.Module):
        def __init__(self):
            super().__init__()
            self.model = policy.model
            enabled = bool(norm.enabled)
            self.register_buffer("scale", norm.scale.detach().cpu().clone() if enabled else torch.ones(obs_dim))
            self.register_buffer("shift", norm.shift.detach().cpu().clone() if enabled else torch.zeros(obs_dim))
            self.clip = float(norm.clip) if enabled else float("inf")
            self.register_buffer("center", const(policy.action_center, 0.0))
            self.register_buffer("half_range", const(policy.action_half, 1.0))
            self.register_buffer("low", const(action_low, -np.inf))
            self.register_buffer("high", const(action_high, np.inf))

        def forward(self, obs):
            x = torch.clamp(obs * self.scale + self.shift, -self.clip, self.clip)
            action = self.center + self.half_range * self.model.actor_mean(x)
            return action, torch.minimum(torch.maximum(action, self.low), self.high)

    return PolicyGraph().eval().to("cpu"), obs_dim


def export_onnx(policy, path: "str | os.PathLike[str]", action_low: Optional[np.ndarray] = None,
                action_high: Optional[np.ndarray] = None) -> None:
    """Write ``policy`` (see :func:`policy_graph_module`) as an ONNX file, atomically."""
    require_extra("onnx", "onnx", "ONNX export")
    import torch

    module, obs_dim = policy_graph_module(policy, action_low, action_high)
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one, which needs onnxscript.
        warnings.simplefilter("ignore")
        torch.onnx.export(module, (torch.zeros(1, obs_dim),), buffer, dynamo=False, opset_version=OPSET,
                          input_names=["obs"], output_names=["action", "clipped_action"],
                          dynamic_axes={"obs": {0: "batch"}, "action": {0: "batch"}, "clipped_action": {0: "batch"}})
    data = buffer.getvalue()
    import onnx

    onnx.checker.check_model(onnx.load_from_string(data))
    atomic_write_bytes(path, data)


def check_onnx(path: "str | os.PathLike[str]", policy, observations: np.ndarray,
               action_low: Optional[np.ndarray] = None, action_high: Optional[np.ndarray] = None) -> dict:
    """onnxruntime against ``policy.act`` over ``observations`` (B, obs_dim):

    - ``action``: the largest |action - act(obs)|;
    - ``action_relative``: the largest |action - act(obs)| / max(1, |act(obs)|) (an untrained
      policy's raw actions reach tens of units, where one float32 ulp is 2e-6);
    - ``clipped_action``: the largest |clipped_action - clip(act(obs), low, high)|, the
      action the env uses (None without a box).
    """
    ort = require_extra("onnxruntime", "onnx", "checking an ONNX export")
    obs = np.ascontiguousarray(observations, np.float32)
    if obs.ndim != 2:
        raise InputError(f"observations: expected (B, obs_dim), got shape {obs.shape}")
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(os.fspath(path), options, providers=["CPUExecutionProvider"])
    action, clipped = session.run(["action", "clipped_action"], {"obs": obs})
    ref = policy.act(obs)
    out = {"action": float(np.max(np.abs(action - ref))),
           "action_relative": float(np.max(np.abs(action - ref) / np.maximum(1.0, np.abs(ref)))),
           "clipped_action": None}
    if action_low is not None and action_high is not None:
        out["clipped_action"] = float(np.max(np.abs(clipped - np.clip(ref, action_low, action_high))))
    return out
