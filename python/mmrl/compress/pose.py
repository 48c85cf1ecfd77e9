"""The pose a compressed controller reproduces (issue 27, docs/compressed.md), and its forward
kinematics in torch.

Learned motion matching (Holden, Kanoun, Perepichka, Popa 2020) replaces the database by networks.
Its decompressor turns a frame's matching features (27, normalized: what the search compares) and
a small latent into that frame's pose. Here "the pose" is what playback needs from a database
frame, in the frame's own character frame so it does not depend on where the clip was recorded:

====================  ==========  ===============================================================
block                 size        meaning
====================  ==========  ===============================================================
``rotations``         J x 6       each joint's local rotation as the first two columns of its
                                  matrix (continuous, Zhou et al. 2019); the root joint's relative
                                  to the character frame's yaw
``translations``      J x 3       each joint's local translation (meters); the root joint's in the
                                  character frame
``root_delta``        3           the character frame's motion to the next frame: (dx, dz) in this
                                  frame's character frame (meters) and dyaw (radians)
``contacts``          2           the left and right foot contacts (1 planted, 0 not): the foot
                                  locking of playback reads them
====================  ==========  ===============================================================

:func:`pose_targets` builds them from a database (one row per frame), :func:`rotation_6d_to_matrix`
and :func:`forward_kinematics` turn a batch back into joint positions for the losses and the
checks.
"""
from __future__ import annotations

from typing import Dict

import numpy as np

__all__ = ["pose_targets", "pose_layout", "pose_dim", "rotation_6d_to_matrix", "forward_kinematics", "quat_to_matrix"]


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)
    return m.reshape(q.shape[:-1] + (3, 3))


def _yaw_matrix(yaw: np.ndarray) -> np.ndarray:
    """(N,) yaws -> (N, 3, 3) rotations about +Y (yaw 0 faces +Z)."""
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(yaw), np.ones_like(yaw)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(-1, 3, 3)


def pose_layout(num_joints: int) -> Dict[str, slice]:
    """Where each block sits in a pose row."""
    j = int(num_joints)
    return {"rotations": slice(0, 6 * j), "translations": slice(6 * j, 9 * j), "root_delta": slice(9 * j, 9 * j + 3),
            "contacts": slice(9 * j + 3, 9 * j + 5)}


def pose_dim(num_joints: int) -> int:
    """Floats in a pose row of a skeleton with ``num_joints`` joints."""
    return 9 * int(num_joints) + 5


def pose_targets(db) -> np.ndarray:
    """(N, 9 J + 5) float32: every frame's pose in its character frame (module docstring)."""
    rot = quat_to_matrix(np.asarray(db.bone_rotations))                # (N, J, 3, 3) local
    tr = np.asarray(db.bone_translations, np.float64).copy()            # (N, J, 3)
    yaw = np.asarray(db.root_yaws, np.float64)
    inv = np.transpose(_yaw_matrix(yaw), (0, 2, 1))                      # world -> character frame
    root = [j for j, p in enumerate(db.parents) if p < 0]
    for r in root:  # root joints: relative to the character frame
        rot[:, r] = inv @ rot[:, r]
        tr[:, r] = np.einsum("nij,nj->ni", inv, tr[:, r] - np.asarray(db.root_positions, np.float64))
    six = rot[..., :, :2].reshape(rot.shape[0], -1)  # the first two columns, row-major per joint
    out = np.concatenate([six, tr.reshape(tr.shape[0], -1), np.asarray(db.root_deltas, np.float64),
                          np.asarray(db.contacts, np.float64)], 1)
    return out.astype(np.float32)


def rotation_6d_to_matrix(six):
    """torch (..., 6) -> (..., 3, 3): the two columns made orthonormal (Gram-Schmidt), the third
    their cross product. Inverse of taking ``m[..., :, :2]`` row-major."""
    import torch

    a = six.reshape(six.shape[:-1] + (3, 2))
    c1 = torch.nn.functional.normalize(a[..., 0], dim=-1)
    c2 = a[..., 1] - (c1 * a[..., 1]).sum(-1, keepdim=True) * c1
    c2 = torch.nn.functional.normalize(c2, dim=-1)
    c3 = torch.cross(c1, c2, dim=-1)
    return torch.stack([c1, c2, c3], -1)


def forward_kinematics(rotations, translations, parents):
    """torch: local rotation matrices (B, J, 3, 3) and translations (B, J, 3), parents (J,) with
    each parent before its child -> joint positions (B, J, 3) in the frame of the roots."""
    import torch

    g_rot, g_pos = [], []
    for j, p in enumerate(parents):
        if p < 0:
            g_rot.append(rotations[:, j])
            g_pos.append(translations[:, j])
        else:
            g_pos.append(g_pos[p] + (g_rot[p] @ translations[:, j, :, None])[..., 0])
            g_rot.append(g_rot[p] @ rotations[:, j])
    return torch.stack(g_pos, 1)
