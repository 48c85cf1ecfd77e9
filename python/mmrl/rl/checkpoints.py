"""PPO checkpoint files: atomic save, validated load, the network they name, RNG capture.

A checkpoint is a ``torch.save``'d dict with ``format``/``version`` keys plus the keys of
``TrainingState.checkpoint`` (:mod:`mmrl.rl.training_state`): the network (``model`` weights, ``model_class`` its registered
name, ``model_kwargs``), ``optimizer``, ``obs_normalizer``, ``return_rms``, the counters
``global_step``/``iteration``/``wall_s``, ``snapshots``, ``rng``, ``config`` (the PPOConfig as
a dict), ``action_center``/``action_half`` and ``callbacks``. Loading never executes code:
``torch.load(weights_only=True)`` reads only tensors and plain containers, and the network
is rebuilt from the registry in ``mmrl.rl.networks``, never by importing a module the file names.
"""
from __future__ import annotations

import os
import random
from pathlib import Path
from typing import Any, Optional

import numpy as np
import torch
from torch import nn

from ..io import atomic_open, load_plain_torch_file
from .networks import network_class, registered_networks

__all__ = ["CHECKPOINT_FORMAT", "CHECKPOINT_VERSION", "CheckpointError", "save_checkpoint", "load_checkpoint",
           "load_plain_torch_file", "build_network", "capture_rng_state", "restore_rng_state", "save_due_checkpoints"]

CHECKPOINT_FORMAT = "mmrl-ppo-checkpoint"
CHECKPOINT_VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint file is missing, corrupt, or not an mmrl PPO checkpoint."""


def save_checkpoint(state: dict, path: str | os.PathLike) -> Path:
    """Write ``state`` atomically (``mmrl.io.atomic_open``), creating the directory.

    If anything fails, the file already at ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, **state}
    with atomic_open(path, "wb") as file:
        torch.save(payload, file)
    return path


def load_checkpoint(path: str | os.PathLike, map_location: Any = "cpu") -> dict:
    """Load and validate a checkpoint; raise ``CheckpointError`` naming the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    state = load_plain_torch_file(path, CheckpointError, "{path}: not a readable checkpoint (corrupt or truncated?): "
                                  "{error}", map_location)
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path}: not an mmrl PPO checkpoint")
    if state.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: checkpoint version {state.get('version')} is not supported "
                              f"(expected {CHECKPOINT_VERSION})")
    return state


def build_network(state: dict, path: str | os.PathLike) -> nn.Module:
    """The (untrained) network a checkpoint names in ``model_class``, built with its
    ``model_kwargs``. Only registered classes are built (``mmrl.rl.networks.register_network``);
    any other name raises ``CheckpointError`` naming the file and the known networks."""
    stored = state.get("model_class")
    try:
        cls = network_class(str(stored))
    except KeyError:
        raise CheckpointError(
            f"{path}: the network {stored!r} is not registered; known networks: "
            f"{', '.join(registered_networks())}. Register your own class with "
            f"mmrl.rl.networks.register_network before loading") from None
    try:
        return cls(**state.get("model_kwargs", {}))
    except Exception as error:
        raise CheckpointError(f"{path}: cannot rebuild the network {stored}: {error}") from error


# ----------------------------------------------------------------------------- RNG capture

def capture_rng_state(generator: Optional[torch.Generator] = None) -> dict:
    """The global random states (python, numpy, torch, CUDA), plus ``generator``'s under
    "ppo_generator" if given, as tensors and plain values a weights-only load accepts.
    The result is a copy: later draws do not change it."""
    np_state = np.random.get_state()
    state = {
        "python": random.getstate(),
        "numpy": {"keys": torch.from_numpy(np_state[1].astype(np.int64)), "pos": int(np_state[2]),
                  "has_gauss": int(np_state[3]), "cached_gaussian": float(np_state[4])},
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
    }
    if generator is not None:
        state["ppo_generator"] = generator.get_state()
    return state


def restore_rng_state(state: dict, generator: Optional[torch.Generator] = None) -> None:
    """Set the global random states (and ``generator``'s) from ``capture_rng_state``'s output."""
    random.setstate(_as_tuple(state["python"]))
    np_state = state["numpy"]
    np.random.set_state(("MT19937", np_state["keys"].numpy().astype(np.uint32), np_state["pos"],
                         np_state["has_gauss"], np_state["cached_gaussian"]))
    torch.set_rng_state(state["torch"])
    if state["cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    if generator is not None:
        generator.set_state(state["ppo_generator"])


def _as_tuple(value: Any) -> Any:
    # A weights-only load turns python's nested state tuples into lists.
    return tuple(_as_tuple(v) for v in value) if isinstance(value, (list, tuple)) else value


# ----------------------------------------------------------------------------- when to save

def save_due_checkpoints(learner: Any, rng: dict, out_dir: Path, last_saved_step: int) -> int:
    """Rewrite ``out_dir/latest.pt`` once ``cfg.checkpoint_interval_steps`` passed since the
    last save, and write ``snapshot_<N>.pt`` the first time the step reaches each N of
    ``cfg.snapshot_steps``. Returns the step of the last save. ``learner`` is a
    :class:`mmrl.rl.training_state.TrainingState` (not imported: it imports this module)."""
    cfg = learner.cfg
    due = [s for s in cfg.snapshot_steps if s <= learner.global_step and s not in learner.snapshots]
    if not due and learner.global_step - last_saved_step < cfg.checkpoint_interval_steps:
        return last_saved_step
    learner.snapshots.update(due)
    state = learner.checkpoint(rng)
    # Snapshots first: latest.pt lists them as saved, so a kill between the two writes must
    # leave a latest.pt that does not yet list them (the resumed run then writes them again).
    for s in due:
        save_checkpoint(state, out_dir / f"snapshot_{s}.pt")
    save_checkpoint(state, out_dir / "latest.pt")
    return learner.global_step
