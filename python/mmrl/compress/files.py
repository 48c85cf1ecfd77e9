"""The compressed-controller file (``mmrl compress``'s output, docs/compressed.md): written
atomically, read without unpickling code, refused with the file's name and the reason when it is
corrupt, of another version, for another database or not trained to the end."""
from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any, Dict

from .networks import CompressConfig, build_networks

FORMAT = "mmrl-compressed"
VERSION = 2


class CompressedFileError(ValueError):
    """A compressed-controller file is corrupt, of another version or for another database."""


def database_signature(db) -> Dict[str, Any]:
    """What a compressed file must match in a database: frames, joints and their names."""
    return {"num_frames": int(db.num_frames), "joint_names": list(db.joint_names), "parents": list(db.parents)}


def config_from(saved: Dict[str, Any]):
    """A file's CompressConfig (fields it lacks keep their defaults)."""
    cfg = CompressConfig()
    for k, v in saved.items():
        if hasattr(cfg, k):
            setattr(cfg, k, tuple(v) if isinstance(getattr(cfg, k), tuple) else v)
    return cfg


def save_compressed(path, nets: Dict[str, Any], data, cfg, db,
                    state: Dict[str, Any]) -> None:
    """Writes the file atomically: the networks trained so far, the normalizations, the
    database's signature and ``state`` (stage, iteration, optimizer, RNG)."""
    import torch

    from ..io import atomic_open

    config = {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()}
    payload = {"format": FORMAT, "version": VERSION, "config": config,
               "y_mean": torch.as_tensor(data.y_mean), "y_std": torch.as_tensor(data.y_std),
               "database": database_signature(db), **{k: v.state_dict() for k, v in nets.items()}, **state}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(Path(path), "wb") as f:
        torch.save(payload, f)


def load_compressed(path, db=None) -> Dict[str, Any]:
    """A compressed file's contents (tensors and plain values only: never unpickles code).
    With ``db``, refuses a file made for another database, naming the difference."""
    from ..io import load_plain_torch_file

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such compressed-controller file")
    state = load_plain_torch_file(path, CompressedFileError, "{path}: corrupt or unreadable compressed file ({error})")
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise CompressedFileError(f"{path}: not an mmrl compressed-controller file")
    if state.get("version") != VERSION:
        raise CompressedFileError(f"{path}: compressed file version {state.get('version')}, this mmrl reads "
                                  f"version {VERSION}")
    if db is not None:
        sig, want = state.get("database", {}), database_signature(db)
        for key in ("num_frames", "joint_names", "parents"):
            if sig.get(key) != want[key]:
                raise CompressedFileError(f"{path}: made for another database ({key} differ: the file's "
                                          f"{str(sig.get(key))[:60]}, the database's {str(want[key])[:60]})")
    return state


def networks_from(state: Dict[str, Any], pose_dim: int, feature_dim: int = 27):
    """(compressor, decompressor, config) of a file, in eval mode."""
    nets, cfg = all_networks_from(state, pose_dim, feature_dim)
    return nets["compressor"], nets["decompressor"], cfg


def all_networks_from(state: Dict[str, Any], pose_dim: int, feature_dim: int = 27):
    """({name: network} of every network the file holds, config), in eval mode."""
    cfg = config_from(state["config"])
    nets = build_networks(pose_dim, feature_dim, cfg)
    out = {}
    for name, net in nets.items():
        if name in state:
            try:
                net.load_state_dict(state[name])
            except (RuntimeError, KeyError) as e:
                raise CompressedFileError(f"the file's {name} does not fit its config: {str(e)[:120]}") from None
            out[name] = net.eval()
    return out, cfg


def stage_of(state: Dict[str, Any]) -> str:
    """The stage a file is in: the network training now, or "done"."""
    return str(state.get("stage", "decompressor" if "stepper" not in state else "done"))


