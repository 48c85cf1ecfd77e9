"""A trained compressed controller, ready to play (docs/compressed.md): the networks of a
``mmrl compress`` file in the C++ core (``_core.CompressedModel``, cpp/include/mmrl/compressed.hpp),
with every database frame's state [X, Zn] for episode starts.

The full path (:class:`mmrl.rollout.FullPath` with ``compressed=``) hands it to the task's env,
which then decides by the projector and plays by the stepper and the decompressor; the character
shows the decoded poses with the database path's inertialization, foot locking and IK.
"""
from __future__ import annotations

from pathlib import Path
from typing import Union

import numpy as np

from .. import _core
from .pose import pose_dim, pose_layout
from .files import CompressedFileError, all_networks_from, load_compressed, stage_of
from .networks import CompressData
from .playback import CompressedPlayback

__all__ = ["CompressedModel", "linear_layers"]


def linear_layers(net) -> list:
    """[(weight (out, in), bias (out,)) float32] of an MLP's linear layers, in order."""
    from torch import nn

    return [(np.ascontiguousarray(m.weight.detach().cpu().numpy(), np.float32),
             np.ascontiguousarray(m.bias.detach().cpu().numpy(), np.float32))
            for m in net if isinstance(m, nn.Linear)]


class CompressedModel:
    """The compressed controller of ``path`` for database ``db`` (CompressedFileError when the
    file is corrupt, for another database, or not trained to the end)."""

    def __init__(self, path: Union[str, Path], db):
        import torch

        self.path = Path(path)
        state = load_compressed(self.path, db)
        if stage_of(state) != "done":
            raise CompressedFileError(f"{self.path}: its training stopped in the {stage_of(state)} stage; finish it "
                                      f"with mmrl compress ... -o {self.path.name} --resume")
        J = int(db.num_joints)
        nets, self.config = all_networks_from(state, pose_dim(J))
        missing = [n for n in ("compressor", "decompressor", "stepper", "projector") if n not in nets]
        if missing or "z_mean" not in state:
            raise CompressedFileError(f"{self.path}: lacks {', '.join(missing) or 'the latent normalization'}")
        self.y_mean = np.asarray(state["y_mean"], np.float32)
        self.y_std = np.asarray(state["y_std"], np.float32)
        self.z_mean = np.asarray(state["z_mean"], np.float32)
        self.z_std = np.asarray(state["z_std"], np.float32)
        data = CompressData.from_database(db, 0)
        # Bones keep their lengths: joints whose translation never changes get it exactly.
        lay = pose_layout(J)
        tr = data.y[:, lay["translations"]].reshape(-1, J, 3)
        self.fixed_joints = (np.abs(tr - tr[:1]).max(axis=(0, 2)) <= 1e-6).astype(np.uint8)
        self.fixed_translations = np.ascontiguousarray(tr[0], np.float32)
        with torch.no_grad():
            y = torch.as_tensor((data.y - self.y_mean) / self.y_std)
            z = torch.cat([nets["compressor"](y[a:a + 8192]) for a in range(0, y.shape[0], 8192)]).numpy()
        states = np.concatenate([data.x, (z - self.z_mean) / self.z_std], 1).astype(np.float32)
        self.networks = nets
        self.frame_states = states  # (N, 27 + latent): every database frame's state
        self.core = _core.CompressedModel(J, int(self.config.latent), linear_layers(nets["decompressor"]),
                                          linear_layers(nets["stepper"]), linear_layers(nets["projector"]),
                                          self.y_mean, self.y_std, self.z_mean, self.z_std,
                                          np.ascontiguousarray(states), self.fixed_joints, self.fixed_translations)
        self.num_joints = J

    @property
    def memory_bytes(self) -> int:
        """Bytes of the networks the runtime keeps (decompressor, stepper, projector, normalizations)."""
        return int(self.core.memory_bytes)

    def playback(self, db) -> "CompressedPlayback":
        """How the full path shows this controller's decisions (:mod:`mmrl.compress.playback`)."""
        return CompressedPlayback(self, db)

    def decode(self, states: np.ndarray) -> np.ndarray:
        """Pose rows (N, 9 J + 5) of states (N, 27 + latent)."""
        return self.core.decode(np.ascontiguousarray(states, np.float32))


def natural_motion(rows: np.ndarray, parents) -> np.ndarray:
    """(F, J, 3) the animation's own motion of each shown row k = 1 .. F of a playback's rows
    (F + 1, 9 J + 5): its joint positions minus row k - 1's, both in row k's character frame
    (row k - 1 moved by the inverse of its root delta). What a pose jump is measured against,
    as a database frame's predecessor is on the database path (mmrl.metrics.pose_jumps)."""
    import torch

    from .networks import _positions

    rows = np.asarray(rows, np.float64)
    J = len(parents)
    with torch.no_grad():
        p = _positions(torch.as_tensor(rows), list(parents), J).numpy()  # (F + 1, J, 3), own frames
    d = rows[:-1, 9 * J:9 * J + 3]  # row k - 1's motion to row k, in row k - 1's frame
    prev = p[:-1].copy()
    prev[..., 0] -= d[:, None, 0]
    prev[..., 2] -= d[:, None, 1]
    c, s = np.cos(d[:, 2]), np.sin(d[:, 2])  # rotate by -dyaw about +Y
    x, z = prev[..., 0].copy(), prev[..., 2].copy()
    prev[..., 0] = c[:, None] * x - s[:, None] * z
    prev[..., 2] = s[:, None] * x + c[:, None] * z
    return p[1:] - prev


def __getattr__(name: str):
    if name == "CompressedController":  # the name until this release: one name per concept
        import warnings

        warnings.warn("mmrl.compress.model.CompressedController is deprecated; use CompressedModel (the C++ "
                      "core's name too)", DeprecationWarning, stacklevel=2)
        return CompressedModel
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
