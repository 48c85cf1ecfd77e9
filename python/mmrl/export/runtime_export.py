"""``mmrl export``: a trained run as one controller file for the C++ runtime, and back.

:func:`controller_sections` gathers what ``mmrl_runtime`` needs (docs/runtime.md lists every
section): the database's saved arrays, the policy's layers with its observation
normalization and action rescaling, the task's numbers and the character's options.
:func:`write_controller` writes them with :mod:`mmrl.runtime_file`; :func:`read_controller`
reads a file back into a Database, a numpy policy and the constants (tests, tools).
Everything is float32 as trained: no quantization.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from .. import _core
from ..errors import InputError
from .runtime_file import ControllerFileError, Section, read_sections, write_sections

__all__ = ["POLICY_MLP", "POLICY_CONV", "ACTIVATIONS", "CHARACTER_DEFAULTS", "controller_sections",
           "write_controller", "read_controller", "ControllerContents", "policy_sections"]

POLICY_MLP, POLICY_CONV = 1, 2
#: Activation codes after a layer.
ACTIVATIONS = {"none": 0, "tanh": 1, "relu": 2}
#: The full path's character options (mmrl.rollout.FullPath's defaults).
CHARACTER_DEFAULTS = {"inertialization_halflife": 0.1, "ik": 1.0, "foot_locking": 1.0}
_DB_ARRAYS = ("parents", "offsets", "end_sites", "has_end_site", "clip_ranges", "clip_mirrored", "bone_translations",
              "bone_rotations", "root_positions", "root_yaws", "root_deltas", "features", "contacts", "feature_mean",
              "block_scale", "weights")
_DB_TEXT = ("joint_names", "channels", "clip_names")


def _dense_layers(modules) -> List[Tuple[object, str]]:
    """(Linear, activation name) of a run of Linear / Tanh / ReLU modules."""
    from torch import nn

    out: List[list] = []
    for m in modules:
        if isinstance(m, nn.Linear):
            out.append([m, "none"])
        elif isinstance(m, (nn.Tanh, nn.ReLU)) and out and out[-1][1] == "none":
            out[-1][1] = "tanh" if isinstance(m, nn.Tanh) else "relu"
        else:
            raise InputError(f"the runtime cannot evaluate a {type(m).__name__} layer (Linear, Tanh, ReLU only)")
    return [tuple(x) for x in out]


def _f32(t) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy(), np.float32)


def _network_layers(model) -> Tuple[list, list, list]:
    """(header fields, conv layers, dense layers) of a registered network."""
    from torch import nn

    from ..rl.networks import MLPActorCritic, ObstacleActorCritic, PlaneActorCritic

    if isinstance(model, (PlaneActorCritic, MLPActorCritic)):
        return [POLICY_MLP, 0, 0, 0, 0, 0, 0], [], _dense_layers(model.actor)
    if isinstance(model, ObstacleActorCritic):
        tower = model.actor
        convs = []
        for m in tower.conv:
            if isinstance(m, nn.Conv2d):
                if m.stride != (1, 1) or m.padding != (0, 0) or m.dilation != (1, 1) or m.groups != 1:
                    raise InputError("the runtime's convolutions are stride 1, no padding, no dilation, no groups")
                convs.append([m, "none"])
            elif isinstance(m, nn.ReLU) and convs:
                convs[-1][1] = "relu"
            elif not isinstance(m, nn.Flatten):
                raise InputError(f"the runtime cannot evaluate a {type(m).__name__} layer in a conv tower")
        if not model._vector_contiguous:
            raise InputError("the runtime needs the obstacle network's vector segments in one contiguous run")
        c, h, w = model.map_shape
        header = [POLICY_CONV, model._map_slice.start, c, h, w, model._vector_slice.start,
                  model._vector_slice.stop - model._vector_slice.start]
        dense = _dense_layers(tower.map_fc) + _dense_layers(tower.head)
        return header, [tuple(x) for x in convs], dense
    raise InputError(f"the runtime has no evaluator for the network {type(model).__name__} "
                     "(PlaneActorCritic, MLPActorCritic and ObstacleActorCritic are supported)")


def policy_sections(policy) -> Dict[str, Section]:
    """The policy's sections: header, layers, observation normalization, action rescaling."""
    model, norm = policy.model, policy.obs_normalizer
    obs_dim, act_dim = int(norm.scale.shape[0]), int(model.log_std.shape[0])
    fields, convs, dense = _network_layers(model)
    out: Dict[str, Section] = {}
    # header: kind, obs_dim, act_dim, conv count, dense count, then the map layout (conv kind).
    header = [fields[0], obs_dim, act_dim, len(convs), len(dense)] + fields[1:]
    out["policy.header"] = np.array(header, np.int32)
    out["policy.activations"] = np.array([ACTIVATIONS[a] for _, a in convs + dense], np.int32)
    for kind, layers in (("conv", convs), ("dense", dense)):
        for k, (layer, _) in enumerate(layers):
            out[f"policy.{kind}{k}.weight"] = _f32(layer.weight)
            out[f"policy.{kind}{k}.bias"] = _f32(layer.bias)
    enabled = bool(norm.enabled)
    out["policy.obs_scale"] = _f32(norm.scale) if enabled else np.ones(obs_dim, np.float32)
    out["policy.obs_shift"] = _f32(norm.shift) if enabled else np.zeros(obs_dim, np.float32)
    out["policy.obs_clip"] = np.array([norm.clip if enabled else np.inf], np.float32)
    center = np.zeros(act_dim, np.float32) if policy.action_center is None else policy.action_center
    half = np.ones(act_dim, np.float32) if policy.action_half is None else policy.action_half
    out["policy.action_center"] = np.asarray(center, np.float32).reshape(act_dim)
    out["policy.action_half"] = np.asarray(half, np.float32).reshape(act_dim)
    for name, values in out.items():  # a diverged policy would export and act NaN in the engine
        if name != "policy.obs_clip" and values.dtype.kind == "f" and not np.isfinite(values).all():
            raise ValueError(f"policy: {name} holds NaN or inf (a diverged training?); not exported")
    return out


def _numbers(prefix: str, values: Dict[str, float]) -> Dict[str, Section]:
    return {f"{prefix}.keys": list(values), f"{prefix}.values": np.array([float(v) for v in values.values()], np.float64)}


def _task_core(task_name: str) -> str:
    """The C++ env core a registered task runs on ("plane", "obstacles"): what the runtime
    builds to observe and decide as training did."""
    from ..tasks import get_task

    try:
        core = str(get_task(task_name).vector_env.core_type.core_name)
    except (KeyError, ValueError):
        raise ValueError(f"task {task_name!r} is not registered: the runtime needs to know its core") from None
    if core not in _core.runtime_task_cores():
        raise ValueError(f"task {task_name!r} runs on the core {core!r}, which the engine runtime has not registered "
                         f"(it has {', '.join(_core.runtime_task_cores())})")
    return core


def controller_sections(db, policy, task_name: str, task_config,
                        character: Optional[Dict[str, float]] = None) -> Dict[str, Section]:
    """Every section of a controller file (docs/runtime.md)."""
    state = db._state()
    out: Dict[str, Section] = {f"db.{k}": list(state[k]) for k in _DB_TEXT}
    out.update({f"db.{k}": np.ascontiguousarray(state[k]) for k in _DB_ARRAYS})
    out["db.roles"] = np.array(state["roles"], np.int32)
    out["db.scalars"] = np.array([state["fps"], state["source_scale"]], np.float32)
    out["db.valid"] = np.ascontiguousarray(db.valid_mask, np.uint8)
    if state["tag_names"]:  # tags on clips (optional; docs/runtime.md)
        out["db.tag_names"] = list(state["tag_names"])
        out["db.clip_tags"] = np.ascontiguousarray(state["clip_tags"], np.uint8)
    out.update(policy_sections(policy))
    out["task.name"] = [task_name]
    out["task.core"] = [_task_core(task_name)]
    skip = set(getattr(task_config, "training_only", ()))  # the trainer's options, not the controller's
    numbers = {k: float(v) for k, v in asdict(task_config).items()
               if isinstance(v, (bool, int, float)) and k not in skip}
    out.update(_numbers("task", numbers))
    clip_costs = getattr(task_config, "clip_costs", "")
    if clip_costs:  # the decision's clip-cost filter, one cost per clip (docs/runtime.md)
        from ..motion.clip_costs import clip_cost_array

        out["task.clip_costs"] = clip_cost_array(clip_costs, db)
    from ..motion.tags import request_group_list

    groups = request_group_list(getattr(task_config, "request_groups", ""))
    if groups:  # the tag groups the policy observes a request code of (docs/styles.md)
        out["task.request_groups"] = groups
    escapes = int(getattr(task_config, "path_escapes", 0)) if getattr(task_config, "path_filter", False) else 0
    if escapes:  # the escapes' nearest frames per frame, so the runtime need not find them at load
        out["task.escape_table"] = db.matcher.escape_table(db._db, escapes, int(task_config.path_fan_candidates))
    out.update(_numbers("character", dict(CHARACTER_DEFAULTS, **(character or {}))))
    return out


def write_controller(path: "str | os.PathLike[str]", db, policy, task_name: str, task_config,
                     character: Optional[Dict[str, float]] = None) -> int:
    """Write the controller file atomically; returns its size in bytes."""
    return write_sections(path, controller_sections(db, policy, task_name, task_config, character))


@dataclass
class ControllerContents:
    """A controller file read back (:func:`read_controller`)."""

    db: object
    task_name: str
    task: Dict[str, float]
    character: Dict[str, float]
    sections: Dict[str, Section]


def _require(path, sections, name):
    if name not in sections:
        raise ControllerFileError(f"{path}: missing section '{name}'")
    return sections[name]


def read_controller(path: "str | os.PathLike[str]") -> ControllerContents:
    """Read a controller file: its Database (rebuilt and validated by the C++ core), the
    task's and character's numbers, and every section."""
    from .. import _core
    from ..motion.database import Database

    s = read_sections(path)
    state = {k: _require(path, s, f"db.{k}") for k in _DB_TEXT + _DB_ARRAYS}
    state = {k: (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v) for k, v in state.items()}
    state["roles"] = [int(r) for r in _require(path, s, "db.roles")]
    if "db.tag_names" in s:
        state["tag_names"] = list(s["db.tag_names"])
        state["clip_tags"] = np.ascontiguousarray(_require(path, s, "db.clip_tags"))
    fps, scale = (float(v) for v in _require(path, s, "db.scalars"))
    state.update(fps=fps, source_scale=scale)
    try:
        db = Database(_core.Database.from_state(state))
    except (ValueError, TypeError) as e:
        raise ControllerFileError(f"{path}: inconsistent database sections ({e})") from e
    if not np.array_equal(db.valid_mask, _require(path, s, "db.valid").astype(bool)):
        raise ControllerFileError(f"{path}: section 'db.valid' disagrees with the clip ranges")

    def numbers(prefix):
        keys, values = _require(path, s, f"{prefix}.keys"), _require(path, s, f"{prefix}.values")
        if len(keys) != len(values):
            raise ControllerFileError(f"{path}: '{prefix}.keys' and '{prefix}.values' differ in length")
        return dict(zip(keys, (float(v) for v in values)))

    return ControllerContents(db, _require(path, s, "task.name")[0], numbers("task"), numbers("character"), s)
