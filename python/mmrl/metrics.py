"""Quality metrics of generated motion, each defined once.

Every motion-quality number mmrl reports comes from this module: ``mmrl eval --json``
(:func:`mmrl.rollout.evaluate_full_path`, for every task: the plane and the moving-obstacles
evaluation run the same loop), ``render``/``export-bvh`` (:func:`mmrl.rollout.follow`), the
benches that call them, ``mmrl db info`` (the raw-mocap floor) and the training log
(:mod:`mmrl.rl.quality_log`).

Definitions (positions in meters, world space; one database frame per shown frame):

- **foot sliding**, cm/s (:func:`foot_contact_speeds`): for each foot (the ``left_foot`` and
  ``right_foot`` roles: the ankles) and each shown frame t whose foot contact is on at both
  t - 1 and t (the database's contacts of the frames shown), the horizontal speed
  |p_t - p_{t-1}| (x and z) * fps. One sample per foot per such frame; summaries are the mean
  and the 95th percentile over all samples (pooled over episodes, not averaged per episode).
  Measured on the shown ankles (IK as the run chose) and on the ankles before foot locking
  and IK (``animated_feet`` of the recording): the ankles of the same run with IK off, since
  IK changes nothing later (``character.hpp``), so one run gives both over the same frames.
- **pose jump**, cm (:func:`pose_jumps`): for each shown frame t, the largest over the body
  joints (the hips and below) of |(p_t - p_{t-1}) - (q_t - q_{t-1})|: the frame's joint
  displacement *in excess of* the displacement of the database frame being played against its
  own predecessor (p in the character frame of the shown root at t, q in the database's
  character frame of the played frame). This is the excess over natural motion: a clip played
  straight scores exactly 0 however fast it moves; what remains is what transitions and
  stitching leave behind (and what IK adds). Summaries: the 99th percentile and the maximum.
- **transitions per second** (:func:`rate_per_second`): decisions whose match was not the
  continuation of the clip being played, per second of shown motion (frames / fps).
- **matched cost**: the squared distance of each decision's query to its matched frame in the
  normalized, weighted feature space (``StepResult.cost``); summary: the mean over decisions.
- **raw-mocap floor** (:func:`raw_mocap_floor`): the same foot sliding and pose jump on the
  database's clips played straight (every pair of consecutive frames of a clip; no matching,
  no IK). Its pose jump is 0 by the definition above (the key is there to show it, not as a
  scale); its foot sliding is what the data itself slides under this contact rule.

Summary keys (:func:`quality`, :class:`QualityAccumulator`; ``None`` when there is nothing to
measure, e.g. on the fast path):

==================================  ========================================================
``foot_sliding_cm_per_s``           mean foot sliding of the shown motion (IK as chosen)
``foot_sliding_p95_cm_per_s``       its 95th percentile
``foot_sliding_ik_off_cm_per_s``    mean foot sliding of the same frames before locking and IK
``foot_sliding_ik_off_p95_cm_per_s``  its 95th percentile
``pose_jump_p99_cm``                99th percentile of the pose jump
``max_pose_jump_cm``                its maximum
``transitions_per_s``               transitions per second of shown motion
``matched_cost_mean``               mean matched cost per decision
==================================  ========================================================

``mmrl eval --json`` adds ``raw_mocap``: ``{foot_sliding_cm_per_s, foot_sliding_p95_cm_per_s,
pose_jump_p99_cm}`` of :func:`raw_mocap_floor`. The training CSV carries the fast-path
``transitions_per_s`` and ``matched_cost`` (:mod:`mmrl.rl.quality_log`).
"""
from __future__ import annotations

import weakref
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from . import _core
from .arrays import as_array, index_array, real_array

#: Percentiles of the summaries.
SLIDING_PERCENTILE = 95.0
JUMP_PERCENTILE = 99.0


# ----------------------------------------------------------------------------- checks
def _points(name: str, value, frames: Optional[int] = None) -> np.ndarray:
    """``value`` as a finite float64 (T, K, 3) array, else TypeError/ValueError naming ``name``."""
    p = real_array(value, name, (None, None, 3), dtype=np.float64, finite=True)
    if frames is not None and p.shape[0] != frames:
        raise ValueError(f"{name}: expected {frames} frames, got {p.shape[0]}")
    return p


def _positive(name: str, value) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name}: expected a positive number, got {value!r}")
    return v


def _percentile(samples: np.ndarray, q: float) -> Optional[float]:
    return float(np.percentile(samples, q)) if samples.size else None


def rate_per_second(count: float, frames: float, fps: float) -> float:
    """``count`` events per second of ``frames`` shown frames at ``fps`` (0 for no frames)."""
    return float(count) * _positive("fps", fps) / frames if frames > 0 else 0.0


# ----------------------------------------------------------------------------- foot sliding
def foot_contact_speeds(positions: np.ndarray, contacts: np.ndarray, foot_joints: Sequence[int],
                        fps: float) -> np.ndarray:
    """The foot-sliding samples (cm/s) of one continuous motion (see the module docstring).

    Args:
        positions: (T, J, 3) world positions, meters.
        contacts: (T, 2) bool, left/right contact of each frame.
        foot_joints: the (left, right) joint indices measured (the ankles).
        fps: frames per second.

    Returns the speeds |p_t - p_{t-1}| (x and z) * fps * 100 of each foot at each frame t in
    contact on both t - 1 and t: the left foot's samples, then the right foot's.
    """
    p = _points("positions", positions)
    c = as_array(contacts, "contacts")
    if c.shape != (p.shape[0], 2):
        raise ValueError(f"contacts: expected shape ({p.shape[0]}, 2) to match the {p.shape[0]} frames of "
                         f"positions, got {c.shape}")
    c = c.astype(bool)
    feet = np.asarray(foot_joints, np.int64)
    if feet.shape != (2,) or (feet < 0).any() or (feet >= p.shape[1]).any():
        raise ValueError(f"foot_joints: expected two joint indices in [0, {p.shape[1]}), got {foot_joints!r}")
    fps = _positive("fps", fps)
    out = []
    for side, j in enumerate(feet):
        d = np.diff(p[:, j, :], axis=0)
        both = c[1:, side] & c[:-1, side]
        out.append(100.0 * fps * np.hypot(d[both, 0], d[both, 2]))
    return np.concatenate(out)


def foot_sliding(positions: np.ndarray, contacts: np.ndarray, foot_joints: Sequence[int], fps: float) -> float:
    """Mean foot sliding (cm/s) of :func:`foot_contact_speeds`; 0 when no foot is in contact."""
    s = foot_contact_speeds(positions, contacts, foot_joints, fps)
    return float(s.mean()) if s.size else 0.0


def foot_sliding_p95(positions: np.ndarray, contacts: np.ndarray, foot_joints: Sequence[int], fps: float) -> float:
    """95th percentile of :func:`foot_contact_speeds` (cm/s); 0 when no foot is in contact."""
    s = foot_contact_speeds(positions, contacts, foot_joints, fps)
    return float(np.percentile(s, SLIDING_PERCENTILE)) if s.size else 0.0


# ----------------------------------------------------------------------------- pose jumps
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


def _jump_excess(p_now: np.ndarray, p_prev: np.ndarray, roots_now: np.ndarray, frames_now: np.ndarray, db,
                 joints: np.ndarray, natural: Optional[np.ndarray] = None) -> np.ndarray:
    """Pose jump (cm) of M frame pairs: shown positions now and before (M, J, 3), the shown
    root (x, z, yaw) now (M, 3) and the database frame played now (M,); or, with ``natural``
    (M, J, 3), the played animation's own motion given directly (a compressed controller's)."""
    if natural is None:
        f = frames_now
        clip_start = np.asarray(db.clip_ranges)[np.asarray(db.frame_clip)[f], 0]
        prev = np.where(f > clip_start, f - 1, f)  # the first frame of a clip has no predecessor
        q_now = _core.database_global_positions(db._db, np.ascontiguousarray(f))[:, joints].astype(np.float64)
        q_prev = _core.database_global_positions(db._db, np.ascontiguousarray(prev))[:, joints].astype(np.float64)
        rp, ry = np.asarray(db.root_positions, np.float64)[f][:, [0, 2]], np.asarray(db.root_yaws, np.float64)[f]
        dq = _to_character_frame(q_now, rp, ry) - _to_character_frame(q_prev, rp, ry)
    else:
        dq = np.asarray(natural, np.float64)[:, joints]
    origin, yaw = roots_now[:, :2], roots_now[:, 2]
    dp = _to_character_frame(p_now[:, joints], origin, yaw) - _to_character_frame(p_prev[:, joints], origin, yaw)
    return 100.0 * np.linalg.norm(dp - dq, axis=-1).max(axis=-1)


def pose_jumps(positions: np.ndarray, roots: np.ndarray, frames: np.ndarray, db, joints=None,
               natural: Optional[np.ndarray] = None) -> np.ndarray:
    """Per-frame pose jump (T - 1,), cm, of one continuous motion: for t = 1 .. T - 1 the
    largest over ``joints`` of |(p_t - p_{t-1}) - (q_t - q_{t-1})| (see the module docstring).

    Args:
        positions: (T, J, 3) shown world positions, meters.
        roots: (T, 3) shown world root (x, z, yaw in radians).
        frames: (T,) database frame shown at each t (ignored with ``natural``).
        joints: default :func:`body_joints` (the hips and below).
        natural: (T - 1, J, 3) q_t - q_{t-1} given directly, in the character frame of t: a
            compressed controller's decoded frame against its stepper predecessor
            (:func:`mmrl.compress.model.natural_motion`).

    p is the shown pose and q the database pose of the frame played at t, taken against its
    own predecessor in the database; p in the character frame of the world root at t, q in
    the database's character frame of the played frame. This already measures the excess over
    natural motion: a seamless continuation scores 0 however fast the body moves.
    """
    p = _points("positions", positions)
    T = p.shape[0]
    if p.shape[1] != db.num_joints:
        raise ValueError(f"positions: expected the database's {db.num_joints} joints, got {p.shape[1]}")
    r = real_array(roots, "roots", (T, 3), dtype=np.float64, finite=True)
    joints = body_joints(db) if joints is None else index_array(joints, "joints", (None,), high=db.num_joints)
    if natural is not None:
        natural = real_array(natural, "natural", (T - 1, db.num_joints, 3), dtype=np.float64, finite=True)
        return np.zeros(0) if T < 2 else _jump_excess(p[1:], p[:-1], r[1:], None, db, joints, natural)
    f = as_array(frames, "frames")
    if f.shape != (T,) or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"frames: expected {T} integer frame indices to match positions, got {f.dtype} {f.shape}")
    f = index_array(f, "frames", (T,), high=db.num_frames, what="the database's frames")
    if T < 2:
        return np.zeros(0)
    return _jump_excess(p[1:], p[:-1], r[1:], f[1:], db, joints)


def max_pose_jump(positions: np.ndarray, roots: np.ndarray, frames: np.ndarray, db, joints=None) -> float:
    """The largest :func:`pose_jumps` value, cm (0 for fewer than two frames)."""
    j = pose_jumps(positions, roots, frames, db, joints)
    return float(j.max()) if j.size else 0.0


def transitions_per_second(transitions: np.ndarray, frames_per_step: int, fps: float) -> float:
    """Transitions (one flag per step, every step played in full) per second of played motion."""
    t = as_array(transitions, "transitions")
    if t.ndim != 1:
        raise ValueError(f"transitions: expected one flag per step (S,), got shape {t.shape}")
    if int(frames_per_step) < 1:
        raise ValueError(f"frames_per_step: expected >= 1, got {frames_per_step!r}")
    return rate_per_second(int(t.astype(bool).sum()), t.size * int(frames_per_step), fps)


# ----------------------------------------------------------------------------- summaries
def feet(db) -> List[int]:
    """The (left, right) ankle joints whose sliding is measured (the ``*_foot`` roles)."""
    return [db.joint_names.index(db.roles["left_foot"]), db.joint_names.index(db.roles["right_foot"])]


class QualityAccumulator:
    """Pools the samples of several recordings (episodes) into one summary (module docstring keys).

    ``add(db, recording)`` takes a controller recording (``Character.recording``, full path;
    trimmed to the frames shown) and returns that episode's own summary.
    """

    def __init__(self):
        self.samples: Dict[str, List[np.ndarray]] = {"sliding": [], "sliding_ik_off": [], "jumps": [], "costs": []}
        self.transitions = 0
        self.frames = 0
        self.fps: Optional[float] = None

    @staticmethod
    def samples_of(db, recording) -> Dict[str, Any]:
        rec = recording
        missing = [k for k in ("positions", "roots", "frames", "contacts", "transitions") if k not in rec]
        if missing:
            raise ValueError(f"recording: missing {', '.join(missing)} (a full-path Character recording)")
        contacts = np.asarray(rec["contacts"])
        out = {"sliding": foot_contact_speeds(rec["positions"], contacts, feet(db), db.fps),
               "jumps": pose_jumps(rec["positions"], rec["roots"], rec["frames"], db,
                                   natural=rec.get("natural_motion")),
               "costs": np.asarray(rec.get("costs", np.zeros(0)), np.float64).reshape(-1),
               "transitions": int(np.asarray(rec["transitions"]).astype(bool).sum()),
               "frames": int(np.asarray(rec["frames"]).shape[0]) - 1}  # shown after the reset pose
        if "animated_feet" in rec:
            out["sliding_ik_off"] = foot_contact_speeds(rec["animated_feet"], contacts, (0, 1), db.fps)
        return out

    def add(self, db, recording) -> Dict[str, Any]:
        s = self.samples_of(db, recording)
        for key in self.samples:
            if key in s:
                self.samples[key].append(s[key])
        self.transitions += s["transitions"]
        self.frames += s["frames"]
        self.fps = db.fps
        return _summary({k: [s[k]] for k in self.samples if k in s}, s["transitions"], s["frames"], db.fps)

    def result(self) -> Dict[str, Any]:
        """The pooled summary (every key None before the first ``add``)."""
        return _summary(self.samples, self.transitions, self.frames, self.fps or 1.0)


def _summary(samples: Dict[str, List[np.ndarray]], transitions: int, frames: int, fps: float) -> Dict[str, Any]:
    """The summary keys from pooled samples; None where a key had no recording to measure."""
    cat = {k: np.concatenate(v) if v else None for k, v in samples.items()}

    def stat(key, fn):
        a = cat.get(key)
        return None if a is None else fn(a)

    # No contact (or fewer than two frames) is no sliding (no jump).
    empty_is_zero = lambda fn: (lambda a: fn(a) if a.size else 0.0)  # noqa: E731
    return {
        "foot_sliding_cm_per_s": stat("sliding", empty_is_zero(lambda a: float(a.mean()))),
        "foot_sliding_p95_cm_per_s": stat("sliding", empty_is_zero(lambda a: _percentile(a, SLIDING_PERCENTILE))),
        "foot_sliding_ik_off_cm_per_s": stat("sliding_ik_off", empty_is_zero(lambda a: float(a.mean()))),
        "foot_sliding_ik_off_p95_cm_per_s": stat("sliding_ik_off",
                                                 empty_is_zero(lambda a: _percentile(a, SLIDING_PERCENTILE))),
        "pose_jump_p99_cm": stat("jumps", empty_is_zero(lambda a: _percentile(a, JUMP_PERCENTILE))),
        "max_pose_jump_cm": stat("jumps", empty_is_zero(lambda a: float(a.max()))),
        "transitions_per_s": None if cat.get("jumps") is None else rate_per_second(transitions, frames, fps),
        "matched_cost_mean": stat("costs", lambda a: float(a.mean()) if a.size else None),
    }


def quality(db, recording) -> Dict[str, Any]:
    """The motion-quality summary (module docstring keys) of one controller recording
    (``Character.recording``, full path)."""
    return QualityAccumulator().add(db, recording)


# ----------------------------------------------------------------------------- raw-mocap floor
_FLOOR_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_FLOOR_CHUNK_FRAMES = 1 << 15  # FK of this many frames at a time: bounded memory on any database


def raw_mocap_floor(db, only: Optional[np.ndarray] = None) -> Dict[str, float]:
    """Foot sliding and pose jump of the database's clips played straight (no matching, no IK).

    Every pair of consecutive frames inside a clip is one step of playback: the same contact
    rule, foot sliding and pose-jump excess as generated motion (module docstring), over all
    clips of the database (mirrored copies included). Computed once per database object.
    Returns ``foot_sliding_cm_per_s``, ``foot_sliding_p95_cm_per_s``, ``pose_jump_p99_cm``
    (0: a clip played straight is its own reference) and ``frames`` (the pairs measured).
    ``only``: (num_frames,) bool, measure just the pairs (t - 1, t) whose frame t it selects
    (the idle frames: :func:`mmrl.eval.standing.raw_idle_floor`); not cached.
    """
    if only is not None:
        only = np.asarray(only)
        if only.shape != (db.num_frames,) or only.dtype != bool:
            raise ValueError(f"only: expected ({db.num_frames},) bool, got {only.dtype} {only.shape}")
    cached = _FLOOR_CACHE.get(db) if only is None else None
    if cached is not None:
        return dict(cached)
    ranges = np.asarray(db.clip_ranges, np.int64)
    contacts = np.asarray(db.contacts, bool)
    feet_idx, body = feet(db), body_joints(db)
    roots = np.column_stack([np.asarray(db.root_positions, np.float64)[:, [0, 2]],
                             np.asarray(db.root_yaws, np.float64)])
    speeds, jumps = [], []
    pairs = 0
    a = 0
    while a < len(ranges):  # chunks of whole clips
        b = a + 1
        while b < len(ranges) and ranges[b, 1] - ranges[a, 0] <= _FLOOR_CHUNK_FRAMES:
            b += 1
        lo, hi = int(ranges[a, 0]), int(ranges[b - 1, 1])
        frames = np.arange(lo, hi, dtype=np.int64)
        p = _core.database_global_positions(db._db, frames).astype(np.float64)
        # Pairs (t - 1, t) inside one clip: t is not a clip's first frame.
        starts = ranges[a:b, 0] - lo
        now = np.ones(hi - lo, bool)
        now[starts] = False
        if only is not None:
            now &= only[lo:hi]
        t = np.flatnonzero(now)
        pairs += t.size
        for side, j in enumerate(feet_idx):
            both = contacts[lo + t, side] & contacts[lo + t - 1, side]
            d = p[t[both], j] - p[t[both] - 1, j]
            speeds.append(100.0 * db.fps * np.hypot(d[:, 0], d[:, 2]))
        jumps.append(_jump_excess(p[t], p[t - 1], roots[lo + t], lo + t, db, body))
        a = b
    s, jp = np.concatenate(speeds), np.concatenate(jumps)
    out = {"foot_sliding_cm_per_s": float(s.mean()) if s.size else 0.0,
           "foot_sliding_p95_cm_per_s": _percentile(s, SLIDING_PERCENTILE) or 0.0,
           "pose_jump_p99_cm": _percentile(jp, JUMP_PERCENTILE) or 0.0,
           "frames": int(db.num_frames) if only is None else int(pairs)}
    if only is None:
        _FLOOR_CACHE[db] = dict(out)
    return out
