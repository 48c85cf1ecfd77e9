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

A policy conditioned on requests (``mmrl train --request-groups``, docs/styles.md) takes them as a second
input, so an engine sets the request apart from the observation:

    input  ``obs``            (B, obs_dim - R): the observation without its request code
    input  ``request``        (B, R) float32: the code, one float per tag of the conditioned
                              groups, 1 for the requested values (all 0 leaves a group free);
                              the model's metadata ``mmrl.request_tags`` lists the R tags in
                              order (JSON)

Export uses torch's TorchScript exporter (``dynamo=False``): it needs only ``onnx``, where the
dynamo exporter of torch 2.x also needs ``onnxscript``. Checking needs ``onnxruntime``; both
are the ``mmrl[onnx]`` extra.
"""
from __future__ import annotations

import io
import os
import warnings
from typing import Optional, Sequence

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


def _with_request(module):
    """``(obs, request) -> module(cat(obs, request))``: the graph with the request as its own input."""
    import torch
    from torch import nn

    class Graph(nn.Module):
        def __init__(self):
            super().__init__()
            self.inner = module

        def forward(self, obs, request):
            return self.inner(torch.cat([obs, request], dim=1))

    return Graph().eval()


def export_onnx(policy, path: "str | os.PathLike[str]", action_low: Optional[np.ndarray] = None,
                action_high: Optional[np.ndarray] = None, request_tags: Sequence[str] = ()) -> None:
    """Write ``policy`` (see :func:`policy_graph_module`) as an ONNX file, atomically.
    ``request_tags``: the tags of the request code that ends the policy's observation, in order
    (the env's ``request_tags``); they become the ``request`` input."""
    require_extra("onnx", "onnx", "ONNX export")
    import json

    import torch

    module, obs_dim = policy_graph_module(policy, action_low, action_high)
    r = len(request_tags)
    if r >= obs_dim:
        raise InputError(f"request_tags: {r} tags for an observation of {obs_dim}")
    args = (torch.zeros(1, obs_dim),)
    names = ["obs"]
    if r:
        module = _with_request(module)
        args, names = (torch.zeros(1, obs_dim - r), torch.zeros(1, r)), ["obs", "request"]
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one, which needs onnxscript.
        warnings.simplefilter("ignore")
        torch.onnx.export(module, args, buffer, dynamo=False, opset_version=OPSET,
                          input_names=names, output_names=["action", "clipped_action"],
                          dynamic_axes={**{n: {0: "batch"} for n in names}, "action": {0: "batch"},
                                        "clipped_action": {0: "batch"}})
    import onnx

    model = onnx.load_from_string(buffer.getvalue())
    if r:
        entry = model.metadata_props.add()
        entry.key, entry.value = "mmrl.request_tags", json.dumps(list(request_tags))
    onnx.checker.check_model(model)
    atomic_write_bytes(path, model.SerializeToString())


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
    inputs = {i.name: i for i in session.get_inputs()}
    if "request" in inputs:  # a request-conditioned policy: the code is the observation's last R floats
        r = int(inputs["request"].shape[1])
        feeds = {"obs": obs[:, :-r], "request": obs[:, -r:]}
    else:
        feeds = {"obs": obs}
    action, clipped = session.run(["action", "clipped_action"], feeds)
    ref = policy.act(obs)
    out = {"action": float(np.max(np.abs(action - ref))),
           "action_relative": float(np.max(np.abs(action - ref) / np.maximum(1.0, np.abs(ref)))),
           "clipped_action": None}
    if action_low is not None and action_high is not None:
        out["clipped_action"] = float(np.max(np.abs(clipped - np.clip(ref, action_low, action_high))))
    return out
