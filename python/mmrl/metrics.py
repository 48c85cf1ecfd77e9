"""Quality metrics of generated motion.

- :func:`foot_sliding`: mean horizontal speed of a foot while it is in contact, cm/s;
- :func:`pose_jumps` / :func:`max_pose_jump`: per-frame change of each joint's position in
  the character frame beyond the change in the database frames being played, cm;
- :func:`transitions_per_second`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from . import _core


def _to_character_frame(points: np.ndarray, origin_xz: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(T, J, 3) world points into per-row character frames (origin (T, 2), yaw (T,))."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    dx = points[..., 0] - origin_xz[:, None, 0]
    dz = points[..., 2] - origin_xz[:, None, 1]
    return np.stack([c * dx - s * dz, points[..., 1], s * dx + c * dz], axis=-1)


def body_joints(db) -> np.ndarray:
    """Indices of the hips and every joint below them: the shown body.

    Joints above the hips (a static BVH root dummy, for example) are structural: on the full
    path they carry the map from the database's world to the character's, so their positions
    jump at every transition without being part of the figure.
    """
    parents = db.parents
    hips = db.joint_names.index(db.roles["hips"])
    out = []
    for j in range(len(parents)):
        a = j
        while a >= 0 and a != hips:
            a = parents[a]
        if a == hips:
            out.append(j)
    return np.array(out, np.int64)


def foot_sliding(positions: np.ndarray, contacts: np.ndarray, foot_joints: Sequence[int], fps: float) -> float:
    """Mean horizontal speed (cm/s) of the feet over the frames where they are in contact.

    Args:
        positions: (T, J, 3) world positions, meters.
        contacts: (T, 2) bool, left/right contact of each frame.
        foot_joints: the (left, right) joint indices measured (the ankles).
        fps: frames per second.

    A foot's speed at frame t is |p_t - p_{t-1}| (x and z only) * fps; it counts when the foot
    is in contact on both t - 1 and t. Returns 0 when there is no contact.
    """
    p = np.asarray(positions, np.float64)
    c = np.asarray(contacts, bool)
    if p.ndim != 3 or p.shape[2] != 3 or c.shape != (p.shape[0], 2):
        raise ValueError(f"positions (T, J, 3) and contacts (T, 2) expected, got {p.shape} and {c.shape}")
    total, count = 0.0, 0
    for side, j in enumerate(foot_joints):
        d = np.diff(p[:, j, :], axis=0)
        speed = np.hypot(d[:, 0], d[:, 2]) * fps
        both = c[1:, side] & c[:-1, side]
        total += float(speed[both].sum())
        count += int(both.sum())
    return 100.0 * total / count if count else 0.0


def pose_jumps(positions: np.ndarray, roots: np.ndarray, frames: np.ndarray, db, joints=None) -> np.ndarray:
    """Per-frame pose jump (T - 1,), cm: max over joints of |(p_t - p_{t-1}) - (q_t - q_{t-1})|.

    ``joints`` defaults to :func:`body_joints` (the hips and below).

    p is the shown pose and q the database pose of the frame played at t, taken against its
    own predecessor in the database; p in the character frame of the world root at t, q in
    the database's character frame of the played frame. A seamless continuation scores 0;
    what remains is what stitching leaves behind.
    """
    p = np.asarray(positions, np.float64)
    roots = np.asarray(roots, np.float64)
    frames = np.asarray(frames, np.int64)
    if p.ndim != 3 or p.shape[2] != 3 or roots.shape != (p.shape[0], 3) or frames.shape != (p.shape[0],):
        raise ValueError(f"positions (T, J, 3), roots (T, 3) and frames (T,) expected, got {p.shape}, "
                         f"{roots.shape} and {frames.shape}")
    joints = body_joints(db) if joints is None else np.asarray(joints, np.int64)
    p = p[:, joints]
    T = p.shape[0]
    if T < 2:
        return np.zeros(0)
    f = frames[1:]
    clip_start = np.asarray(db.clip_ranges)[np.asarray(db.frame_clip)[f], 0]
    prev = np.where(f > clip_start, f - 1, f)  # the first frame of a clip has no predecessor
    q_now = _core.database_global_positions(db._db, np.ascontiguousarray(f))[:, joints].astype(np.float64)
    q_prev = _core.database_global_positions(db._db, np.ascontiguousarray(prev))[:, joints].astype(np.float64)
    rp, ry = np.asarray(db.root_positions, np.float64)[f][:, [0, 2]], np.asarray(db.root_yaws, np.float64)[f]
    dq = _to_character_frame(q_now, rp, ry) - _to_character_frame(q_prev, rp, ry)
    origin, yaw = roots[1:, :2], roots[1:, 2]
    dp = _to_character_frame(p[1:], origin, yaw) - _to_character_frame(p[:-1], origin, yaw)
    return 100.0 * np.linalg.norm(dp - dq, axis=-1).max(axis=-1)


def max_pose_jump(positions: np.ndarray, roots: np.ndarray, frames: np.ndarray, db, joints=None) -> float:
    """The largest :func:`pose_jumps` value, cm (0 for fewer than two frames)."""
    j = pose_jumps(positions, roots, frames, db, joints)
    return float(j.max()) if j.size else 0.0


def transitions_per_second(transitions: np.ndarray, frames_per_step: int, fps: float) -> float:
    """Transitions (one flag per step) per second of played motion."""
    t = np.asarray(transitions, bool)
    seconds = t.size * frames_per_step / fps
    return float(t.sum() / seconds) if seconds > 0 else 0.0


def quality(db, recording) -> dict:
    """The motion-quality metrics of a controller recording (``Controller.recording``, full path):
    ``foot_sliding_cm_per_s`` (ankles over the database's contact frames),
    ``max_pose_jump_cm`` and ``transitions_per_s``."""
    feet = [db.joint_names.index(db.roles["left_foot"]), db.joint_names.index(db.roles["right_foot"])]
    rec = recording
    return {
        "foot_sliding_cm_per_s": foot_sliding(rec["positions"], rec["contacts"], feet, db.fps),
        "max_pose_jump_cm": max_pose_jump(rec["positions"], rec["roots"], rec["frames"], db),
        "transitions_per_s": transitions_per_second(rec["transitions"], int(rec["frames_per_step"]), db.fps),
    }
