"""Training the compressor and decompressor of learned motion matching (issue 27, first part;
docs/compressed.md).

The decompressor maps a frame's normalized matching features X (27) and a latent Z to its pose Y
(:mod:`mmrl.compress.pose`); the compressor finds Z from the pose, so that X and Z together
determine the frame. Trained together as an autoencoder whose bottleneck is Z, with the features
given. The losses follow the reference design (Holden et al. 2020, section 4.1): the pose itself
(normalized), joint positions by forward kinematics in the character frame, both as velocities
over consecutive frames too, and a small penalty on the latent and its change between frames.

    mmrl compress DB -o compressed.pt --seconds 600

shows progress, logs metrics.csv (and TensorBoard with mmrl[viz]) beside the output, saves a
checkpoint every ``checkpoint_every`` iterations (atomically), resumes with ``--resume``, and is
reproducible with a seed. It uses CUDA when present.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from .pose import forward_kinematics, pose_layout, pose_targets, rotation_6d_to_matrix

FORMAT = "mmrl-compressed"
VERSION = 1


class CompressedFileError(ValueError):
    """A compressed-controller file is corrupt, of another version or for another database."""


@dataclass
class CompressConfig:
    """Options of ``mmrl compress`` (every field is also ``--set KEY=VALUE``)."""

    latent: int = 32
    """Size of the latent Z."""
    hidden: Tuple[int, ...] = (512, 512)
    """Hidden layer sizes of the compressor and the decompressor (ELU)."""
    batch: int = 256
    """Pairs of consecutive frames per iteration."""
    learning_rate: float = 1e-3
    """Adam's, decayed by ``lr_decay`` every 1,000 iterations."""
    lr_decay: float = 0.97
    iterations: int = 50_000
    """Iterations at most (``--seconds`` may stop sooner)."""
    w_pose: float = 1.0
    w_positions: float = 1.0
    w_velocity: float = 1.0
    w_latent: float = 0.1
    w_latent_velocity: float = 0.01
    holdout_every: int = 10
    """Every k-th clip is held back from training and measured (0: none)."""
    checkpoint_every: int = 2_000
    seed: int = 0
    device: str = "auto"


def _logger():
    """metrics.csv (appended on resume) and TensorBoard, with the compressor's columns."""
    from ..rl.logger import MetricsLogger

    class CompressLogger(MetricsLogger):
        BASE_COLUMNS = ("step", "wall_s", "iteration", "learning_rate", "loss", "pose", "positions_m", "velocity",
                        "latent", "latent_velocity", "joint_error_cm", "holdout_joint_error_cm")
        LOSS_KEYS = ("loss", "pose", "positions_m", "velocity", "latent", "latent_velocity")

    return CompressLogger


def _mlp(sizes: Sequence[int]):
    from torch import nn

    layers = []
    for k in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[k], sizes[k + 1]))
        if k < len(sizes) - 2:
            layers.append(nn.ELU())
    return nn.Sequential(*layers)


def build_networks(pose_dim: int, feature_dim: int, cfg: CompressConfig):
    """(compressor: pose -> Z, decompressor: [X, Z] -> pose), both on normalized rows."""
    return (_mlp([pose_dim, *cfg.hidden, cfg.latent]), _mlp([feature_dim + cfg.latent, *cfg.hidden, pose_dim]))


@dataclass
class CompressData:
    """The training rows of a database: features X, poses Y, their normalization, and the
    (t, t + 1) pairs inside clips, split into training and held-back clips."""

    x: np.ndarray
    y: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray
    parents: list
    train_pairs: np.ndarray
    holdout_pairs: np.ndarray
    holdout_frames: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @classmethod
    def from_database(cls, db, holdout_every: int = 10) -> "CompressData":
        x = np.array(db.normalized_features, np.float32)  # a writable copy (torch shares it)
        y = pose_targets(db)
        ranges = np.asarray(db.clip_ranges)
        held = np.zeros(len(ranges), bool)
        if holdout_every > 0 and len(ranges) > 1:
            held[holdout_every - 1::holdout_every] = True
        pairs_train, pairs_held, frames_held = [], [], []
        for c, (a, b) in enumerate(ranges):
            t = np.arange(a, b - 1, dtype=np.int64)
            (pairs_held if held[c] else pairs_train).append(t)
            if held[c]:
                frames_held.append(np.arange(a, b, dtype=np.int64))
        train = np.concatenate(pairs_train) if pairs_train else np.zeros(0, np.int64)
        mean = y[np.concatenate([train, train + 1])].mean(0) if train.size else y.mean(0)
        std = np.maximum(y[np.concatenate([train, train + 1])].std(0) if train.size else y.std(0), 1e-3)
        return cls(x, y, mean.astype(np.float32), std.astype(np.float32), list(db.parents), train,
                   np.concatenate(pairs_held) if pairs_held else np.zeros(0, np.int64),
                   np.concatenate(frames_held) if frames_held else np.zeros(0, np.int64))


def _positions(y_raw, parents, J):
    """torch: raw pose rows (B, 9J + 3) -> joint positions (B, J, 3) in the character frame."""
    lay = pose_layout(J)
    rot = rotation_6d_to_matrix(y_raw[:, lay["rotations"]].reshape(-1, J, 6))
    tr = y_raw[:, lay["translations"]].reshape(-1, J, 3)
    return forward_kinematics(rot, tr, parents)


def losses(comp, decomp, data_t, idx, cfg: CompressConfig) -> Dict[str, Any]:
    """The losses of one batch of (t, t + 1) pairs (``idx``: the t's)."""
    import torch

    x, y, mean, std, parents, J = data_t
    both = torch.cat([idx, idx + 1])
    yn = (y[both] - mean) / std
    z = comp(yn)
    out_n = decomp(torch.cat([x[both], z], 1))
    out = out_n * std + mean
    true_pos = _positions(y[both], parents, J)
    pos = _positions(out, parents, J)
    n = idx.shape[0]
    l_pose = (out_n - yn).abs().mean()
    l_pos = (pos - true_pos).abs().mean()
    l_vel = ((out_n[n:] - out_n[:n]) - (yn[n:] - yn[:n])).abs().mean() + \
        ((pos[n:] - pos[:n]) - (true_pos[n:] - true_pos[:n])).abs().mean()
    l_z = (z ** 2).mean()
    l_zv = (z[n:] - z[:n]).abs().mean()
    total = cfg.w_pose * l_pose + cfg.w_positions * l_pos + cfg.w_velocity * l_vel + cfg.w_latent * l_z + \
        cfg.w_latent_velocity * l_zv
    return {"loss": total, "pose": l_pose, "positions_m": l_pos, "velocity": l_vel, "latent": l_z,
            "latent_velocity": l_zv, "joint_error_cm": 100.0 * (pos - true_pos).norm(dim=-1).mean()}


def _device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _tensors(data: CompressData, device):
    import torch

    return (torch.as_tensor(data.x, device=device), torch.as_tensor(data.y, device=device),
            torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device),
            list(data.parents), len(data.parents))


def database_signature(db) -> Dict[str, Any]:
    """What a compressed file must match in a database: frames, joints and their names."""
    return {"num_frames": int(db.num_frames), "joint_names": list(db.joint_names), "parents": list(db.parents)}


def save_compressed(path, comp, decomp, data: CompressData, cfg: CompressConfig, db, state: Dict[str, Any]) -> None:
    import torch

    from ..io import atomic_open

    payload = {"format": FORMAT, "version": VERSION, "config": {k: (list(v) if isinstance(v, tuple) else v)
                                                                for k, v in asdict(cfg).items()},
               "compressor": comp.state_dict(), "decompressor": decomp.state_dict(),
               "y_mean": torch.as_tensor(data.y_mean), "y_std": torch.as_tensor(data.y_std),
               "database": database_signature(db), **state}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(Path(path), "wb") as f:
        torch.save(payload, f)


def load_compressed(path, db=None) -> Dict[str, Any]:
    """A compressed file's contents (tensors and plain values only: never unpickles code).
    With ``db``, refuses a file made for another database, naming the difference."""
    from ..rl.checkpoints import load_plain_torch_file

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
    cfg = CompressConfig(**{k: (tuple(v) if k == "hidden" else v) for k, v in state["config"].items()})
    comp, decomp = build_networks(pose_dim, feature_dim, cfg)
    comp.load_state_dict(state["compressor"])
    decomp.load_state_dict(state["decompressor"])
    return comp.eval(), decomp.eval(), cfg


def train_compressed(db, out, cfg: Optional[CompressConfig] = None, *, seconds: Optional[float] = None,
                     resume: bool = False, progress: bool = True, log_dir=None) -> Dict[str, Any]:
    """Train (or resume) the compressor and decompressor of ``db`` into ``out``; returns the last
    metrics (the held-back clips' joint error included)."""
    import torch

    cfg = cfg or CompressConfig()
    out = Path(out)
    device = _device(cfg.device)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    data = CompressData.from_database(db, cfg.holdout_every)
    if data.train_pairs.size == 0:
        raise ValueError("the database has no pair of consecutive frames to train on")
    comp, decomp = build_networks(data.y.shape[1], data.x.shape[1], cfg)
    comp.to(device), decomp.to(device)
    opt = torch.optim.Adam(list(comp.parameters()) + list(decomp.parameters()), lr=cfg.learning_rate)
    start = 0
    if resume and out.exists():
        state = load_compressed(out, db)
        comp.load_state_dict(state["compressor"])
        decomp.load_state_dict(state["decompressor"])
        opt.load_state_dict(state["optimizer"])
        start = int(state["iteration"])
        rng.bit_generator.state = state["rng"]  # the batches a run without the stop would have drawn
    sched = torch.optim.lr_scheduler.StepLR(opt, 1000, gamma=cfg.lr_decay, last_epoch=start - 1 if start else -1)
    data_t = _tensors(data, device)
    log_path = Path(log_dir or out.parent) / f"{out.stem}-metrics"
    log_path.mkdir(parents=True, exist_ok=True)
    logger = _logger()(log_path, start if resume else None, tensorboard=True)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.iterations, initial=start, unit="it", desc="compress")
    t0, it, last = time.perf_counter(), start, {}
    try:
        while it < cfg.iterations and (seconds is None or time.perf_counter() - t0 < seconds):
            idx = torch.as_tensor(rng.choice(data.train_pairs, cfg.batch), device=device)
            res = losses(comp, decomp, data_t, idx, cfg)
            opt.zero_grad()
            res["loss"].backward()
            opt.step()
            sched.step()
            it += 1
            if bar is not None:
                bar.update(1)
            if it % 200 == 0 or it == cfg.iterations:
                last = {k: float(v.detach()) for k, v in res.items()}
                last.update(step=it, wall_s=time.perf_counter() - t0, iteration=it,
                            learning_rate=opt.param_groups[0]["lr"])
                if it % cfg.checkpoint_every == 0:
                    held = holdout_error(comp, decomp, data, device)
                    if held is not None:
                        last["holdout_joint_error_cm"] = held
                    save_compressed(out, comp, decomp, data, cfg, db, {"iteration": it, "optimizer": opt.state_dict(),
                                                                       "rng": rng.bit_generator.state})
                logger.write(last)
    finally:
        if bar is not None:
            bar.close()
    held = holdout_error(comp, decomp, data, device)
    if held is not None:
        last["holdout_joint_error_cm"] = held
    last["iteration"] = it
    save_compressed(out, comp, decomp, data, cfg, db, {"iteration": it, "optimizer": opt.state_dict(),
                                                       "rng": rng.bit_generator.state})
    logger.close()
    return last


def reconstruct(comp, decomp, data: CompressData, frames: np.ndarray, device=None) -> np.ndarray:
    """Raw poses (len(frames), 9J + 3) of ``frames`` through the compressor and decompressor."""
    import torch

    device = device or next(decomp.parameters()).device
    with torch.no_grad():
        y = torch.as_tensor(data.y[frames], device=device)
        mean, std = torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device)
        z = comp((y - mean) / std)
        out = decomp(torch.cat([torch.as_tensor(data.x[frames], device=device), z], 1)) * std + mean
    return out.cpu().numpy()


def joint_errors_cm(data: CompressData, frames: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Per frame, the mean over joints of |p - p_true| (cm), character frame."""
    import torch

    J = len(data.parents)
    with torch.no_grad():
        p = _positions(torch.as_tensor(poses), data.parents, J)
        q = _positions(torch.as_tensor(data.y[frames]), data.parents, J)
    return (100.0 * (p - q).norm(dim=-1).mean(-1)).numpy()


def holdout_error(comp, decomp, data: CompressData, device) -> Optional[float]:
    """Mean joint position error (cm) over the held-back clips' frames (None without them)."""
    frames = data.holdout_frames
    if frames.size == 0:
        return None
    frames = frames[:: max(1, frames.size // 4096)]
    comp.eval(), decomp.eval()
    err = float(joint_errors_cm(data, frames, reconstruct(comp, decomp, data, frames, device)).mean())
    comp.train(), decomp.train()
    return err

