"""A compressed controller file for the C++ runtime (docs/runtime.md, "Compressed controllers"):
the usual sections, with the database cut down to the start frames, plus the networks.

The runtime's characters start on a database frame's state, so the file keeps ``starts``
windows of the training database (31 frames each, the length a valid match frame needs) with
every one of their frames' states; the decisions and playback come from the networks alone. The
windows are spread evenly over the valid frames. The action box is the training database's, so
the same policy output is clipped the same way.
"""
from __future__ import annotations

from typing import Dict

import numpy as np

from .. import _core
from ..motion.database import Database
from .runtime_export import controller_sections
from .runtime_file import Section, write_sections

__all__ = ["COMPRESSED_SECTION_VERSION", "start_database", "compressed_sections", "write_compressed_controller"]

#: The version of the lmm.* sections (cpp/runtime/runtime.cpp reads it).
COMPRESSED_SECTION_VERSION = 1
#: Frames of a start window: a valid match frame needs 30 more in its clip.
WINDOW = _core.MAX_FRAMES_PER_STEP + 1

_PER_FRAME = ("bone_translations", "bone_rotations", "root_positions", "root_yaws", "root_deltas", "features",
              "contacts")


def start_database(db: Database, starts: int = 8):
    """(a database of ``starts`` windows of ``db``, the source frame of each of its frames)."""
    valid = np.flatnonzero(db.valid_mask)
    if starts < 1:
        raise ValueError(f"starts must be >= 1, got {starts}")
    picks = valid[np.unique(np.linspace(0, valid.size - 1, min(starts, valid.size)).round().astype(np.int64))]
    source = (picks[:, None] + np.arange(WINDOW)[None]).reshape(-1)
    state = dict(db._state())
    for k in _PER_FRAME:
        state[k] = np.ascontiguousarray(np.asarray(state[k])[source])
    clips = np.asarray(db.frame_clip)[picks]
    state["clip_ranges"] = np.stack([np.arange(picks.size) * WINDOW, np.arange(1, picks.size + 1) * WINDOW],
                                    1).astype(np.asarray(state["clip_ranges"]).dtype)
    state["clip_names"] = [f"{db.clip_names[c]}@{f}" for c, f in zip(clips, picks)]
    state["clip_mirrored"] = np.ascontiguousarray(np.asarray(state["clip_mirrored"])[clips])
    if "clip_tags" in state:
        state["clip_tags"] = np.ascontiguousarray(np.asarray(state["clip_tags"])[clips])
    return Database(_core.Database.from_state(state)), source


def compressed_sections(db: Database, policy, task, task_config, compressed, starts: int = 8) -> Dict[str, Section]:
    """Every section of a compressed controller file (``compressed``: a CompressedModel of ``db``)."""
    from ..compress.model import linear_layers
    from ..motion.tags import request_group_list

    if not getattr(task.vector_env.core_type, "plays_compressed", False):
        raise ValueError(f"a compressed controller runs on a task core that plays one (this run's task is "
                         f"{task.name!r})")
    if request_group_list(getattr(task_config, "request_groups", "")):
        raise ValueError("a compressed controller keeps to no tags; this policy observes requests (--request-groups)")
    small, source = start_database(db, starts)
    out = controller_sections(small, policy, task.name, task_config)
    nets = compressed.networks
    layers = {n: linear_layers(nets[n]) for n in ("decompressor", "stepper", "projector")}
    out["lmm.header"] = np.array([COMPRESSED_SECTION_VERSION, db.num_joints, compressed.config.latent,
                                  *(len(layers[n]) for n in ("decompressor", "stepper", "projector"))], np.int32)
    for name, ls in layers.items():
        for k, (w, b) in enumerate(ls):
            if not np.all(np.abs(w) <= 65504.0):
                raise ValueError(f"{compressed.path}: a weight of the {name}'s layer {k} is beyond float16's range")
            out[f"lmm.{name}.{k}.weight"] = w.astype(np.float16)  # the core's precision (compressed.hpp)
            out[f"lmm.{name}.{k}.bias"] = b
    for key in ("y_mean", "y_std", "z_mean", "z_std"):
        out[f"lmm.{key}"] = np.ascontiguousarray(getattr(compressed, key), np.float32)
    out["lmm.fixed_joints"] = np.ascontiguousarray(compressed.fixed_joints, np.uint8)
    out["lmm.fixed_translations"] = np.ascontiguousarray(compressed.fixed_translations, np.float32)
    out["lmm.frame_states"] = np.ascontiguousarray(compressed.frame_states[source], np.float32)
    out["lmm.start_sources"] = source.astype(np.int32)
    env = task.make_vector_env(1, db=db, config=task_config, num_threads=1)
    out["lmm.action_box"] = np.stack([env.single_action_space.low, env.single_action_space.high]).astype(np.float32)
    env.close()
    return out


def write_compressed_controller(path, db: Database, policy, task, task_config, compressed, starts: int = 8) -> int:
    """Write the file atomically; returns its size in bytes."""
    return write_sections(path, compressed_sections(db, policy, task, task_config, compressed, starts))
