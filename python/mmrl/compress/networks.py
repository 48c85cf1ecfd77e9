"""The networks of a compressed controller and what they train on (docs/compressed.md): the
config, the four MLPs, a database's training rows, and the projector's training queries. The
training loop (:mod:`mmrl.compress.train`), the file (:mod:`mmrl.compress.files`) and the
measures (:mod:`mmrl.compress.measure`) all build on this module."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, Sequence, Tuple

import numpy as np

from .pose import forward_kinematics, pose_layout, pose_targets, rotation_6d_to_matrix

STAGES = ("decompressor", "stepper", "projector")
"""The networks in the order they train: the stepper learns the latents the compressor found, the
projector the features and latents of the search's answers."""


@dataclass
class CompressConfig:
    """Options of ``mmrl compress`` (every field is also ``--set KEY=VALUE``)."""

    latent: int = 32
    """Size of the latent Z."""
    hidden: Tuple[int, ...] = (512, 512)
    """Hidden layer sizes of the compressor and the decompressor (ELU)."""
    stepper_hidden: Tuple[int, ...] = (256, 256)
    """Hidden layer sizes of the stepper (ELU)."""
    projector_hidden: Tuple[int, ...] = (512, 512)
    """Hidden layer sizes of the projector (ELU)."""
    batch: int = 256
    """Pairs of consecutive frames (decompressor), windows (stepper) or queries (projector) per iteration."""
    learning_rate: float = 1e-3
    """Adam's, decayed by ``lr_decay`` every 1,000 iterations (each network from the start)."""
    lr_decay: float = 0.97
    iterations: int = 50_000
    """Decompressor iterations at most (``--seconds`` may stop sooner)."""
    stepper_iterations: int = 50_000
    projector_iterations: int = 50_000
    stage_time: Tuple[float, ...] = (0.5, 0.25, 0.25)
    """With ``--seconds``: the shares of the budget of the decompressor, the stepper and the
    projector (time a stage leaves unused passes to the next)."""
    stepper_window: int = 16
    """Frames the stepper is rolled out over in training (from a true start)."""
    projector_noise: float = 1.0
    """Largest standard deviation (normalized feature units) of the noise added to the
    projector's training queries."""
    w_pose: float = 1.0
    w_positions: float = 1.0
    w_velocity: float = 1.0
    w_latent: float = 0.1
    w_latent_velocity: float = 0.01
    holdout_every: int = 10
    """Every k-th clip is held back from training the decompressor and measured (0: none)."""
    checkpoint_every: int = 2_000
    seed: int = 0
    device: str = "auto"


def _mlp(sizes: Sequence[int]):
    from torch import nn

    layers = []
    for k in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[k], sizes[k + 1]))
        if k < len(sizes) - 2:
            layers.append(nn.ELU())
    return nn.Sequential(*layers)


def build_networks(pose_dim: int, feature_dim: int, cfg: CompressConfig) -> Dict[str, Any]:
    """The four networks, on normalized rows: compressor (pose -> Z), decompressor ([X, Z] -> pose),
    stepper ([X, Zn] -> its change over one frame) and projector (query -> [X, Zn]); Zn is the
    latent normalized by its mean and deviation over the database."""
    state = feature_dim + cfg.latent
    return {"compressor": _mlp([pose_dim, *cfg.hidden, cfg.latent]),
            "decompressor": _mlp([state, *cfg.hidden, pose_dim]),
            "stepper": _mlp([state, *cfg.stepper_hidden, state]),
            "projector": _mlp([feature_dim, *cfg.projector_hidden, state])}


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
    clip_ranges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    valid: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

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
                   np.concatenate(frames_held) if frames_held else np.zeros(0, np.int64),
                   ranges.astype(np.int64), np.asarray(db._db.valid_mask, bool))

    def windows(self, length: int) -> np.ndarray:
        """The first frames t of every window t .. t + length - 1 inside a clip (every clip: the
        stepper plays the whole database)."""
        starts = [np.arange(a, b - length + 1, dtype=np.int64) for a, b in self.clip_ranges if b - a >= length]
        return np.concatenate(starts) if starts else np.zeros(0, np.int64)


def _positions(y_raw, parents, J):
    """torch: raw pose rows (B, 9J + 5) -> joint positions (B, J, 3) in the character frame."""
    lay = pose_layout(J)
    rot = rotation_6d_to_matrix(y_raw[:, lay["rotations"]].reshape(-1, J, 6))
    tr = y_raw[:, lay["translations"]].reshape(-1, J, 3)
    return forward_kinematics(rot, tr, parents)


def projector_queries(data: CompressData, rng: np.random.Generator, n: int, noise: float) -> np.ndarray:
    """Training queries of the projector (normalized): database features with noise of a random
    size, half of them with the trajectory of another frame (as a policy's queries pair the
    character's pose with a trajectory of its choosing)."""
    valid = np.flatnonzero(data.valid)
    f = rng.choice(valid, n)
    q = data.x[f].copy()
    mixed = rng.random(n) < 0.5
    g = rng.choice(valid, int(mixed.sum()))
    q[mixed, 15:] = data.x[g, 15:]
    q += rng.standard_normal(q.shape).astype(np.float32) * (noise * rng.random((n, 1))).astype(np.float32)
    return q
