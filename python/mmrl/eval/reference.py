"""The equal-speed reference: joysticks at speeds spanning a database's gaits, on the same episodes.

A policy that reaches targets faster than a walking joystick is not comparable to it: faster
motion slides more. The fair comparison is the joystick moving at the policy's own speed. For
every database, :func:`joystick_speeds` picks ``count`` speeds from the data's slowest walk to
its fastest run, :func:`joystick_line` evaluates a :class:`~mmrl.rl.policies.JoystickPolicy` at
each of them (``arrive``: it eases off at the target rather than circling it) on the same
full-path episodes as the policy, and :func:`against_line` reads the
line at the policy's time to target: linear in time between the two joysticks around it; a
policy faster than the fastest joystick is held to the fastest one's value, a slower one to the
slowest one's (docs/quality.md).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..motion.database import Database
from ..rl.policies import TRAJECTORY_FRAMES, JoystickPolicy, frame_speeds

#: What each joystick of the line reports (evaluate_full_path's keys).
LINE_KEYS = ("success_rate", "mean_time_to_target_s", "foot_sliding_ik_off_cm_per_s", "foot_sliding_cm_per_s",
             "transitions_per_s", "pose_jump_p99_cm", "mean_speed_m_per_s")
#: Frames slower than this (m/s) are stops and idles: no joystick reaches a target at their pace.
MIN_GAIT_SPEED = 0.3


def joystick_speeds(db: Database, count: int = 5, request: str = "") -> List[float]:
    """``count`` speeds (m/s), evenly spaced from the data's slowest walk to its fastest run: the
    5th and 95th percentiles of the valid frames' speeds over their next second (frames below
    ``MIN_GAIT_SPEED`` left out); with a ``request``, of the valid frames of its clips only."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 2 <= count <= 20:
        raise ValueError(f"count: expected an int in [2, 20], got {count!r}")
    speed = frame_speeds(db)
    if request:
        from .. import _core

        clips = np.asarray(_core.select_request(db._db, request)[1], bool)
        speed = speed[clips[db.frame_clip[db.valid_mask]]]
    moving = speed[speed >= MIN_GAIT_SPEED]
    if moving.size < 10:
        raise ValueError(f"the database has {moving.size} frames moving at {MIN_GAIT_SPEED} m/s or more over "
                         f"{TRAJECTORY_FRAMES[2]} frames: too few for a joystick line")
    lo, hi = np.percentile(moving, [5, 95])
    if hi - lo < 1e-3:
        hi = lo + 1e-3
    return [float(v) for v in np.linspace(lo, hi, int(count))]


def joystick_line(task, db: Database, *, speeds: Optional[Sequence[float]] = None, episodes: int = 20,
                  seed: int = 0, config=None, stage: Optional[int] = None, **options) -> List[Dict[str, Any]]:
    """One row per speed (default :func:`joystick_speeds`): the joystick at that speed on the
    same full-path episodes (``evaluate_full_path`` with ``seed``), ordered by speed."""
    from ..rollout import evaluate_full_path

    rows = []
    for speed in (joystick_speeds(db) if speeds is None else speeds):
        res = evaluate_full_path(task, db, JoystickPolicy(db, float(speed), arrive=True), episodes=episodes, seed=seed,
                                 config=config, stage=stage, **options)
        rows.append({"speed_m_per_s": float(speed), **{k: res.get(k) for k in LINE_KEYS}})
    return rows


def _read_line(line: Sequence[Dict[str, Any]], by: str, at: Optional[float], key: str) -> Optional[float]:
    """The line's ``key`` at ``at`` on its ``by`` axis: linear between the joysticks around it,
    the end values outside; None when ``at`` or the joysticks' values are missing."""
    pts = sorted((r[by], r[key]) for r in line if r.get(by) is not None and r.get(key) is not None)
    if not pts or at is None:
        return None
    x = np.array([p[0] for p in pts], np.float64)
    v = np.array([p[1] for p in pts], np.float64)
    return float(np.interp(float(at), x, v))  # np.interp holds the end values outside


def line_value(line: Sequence[Dict[str, Any]], time_to_target_s: Optional[float],
               key: str = "foot_sliding_ik_off_cm_per_s") -> Optional[float]:
    """The line's ``key`` at ``time_to_target_s``: linear between the joysticks around that time,
    the fastest one's below the fastest time, the slowest one's above the slowest; None when no
    joystick reached a target or the time is None."""
    return _read_line(line, "mean_time_to_target_s", time_to_target_s, key)


def line_value_at_speed(line: Sequence[Dict[str, Any]], speed_m_per_s: Optional[float],
                        key: str = "foot_sliding_ik_off_cm_per_s") -> Optional[float]:
    """The line's ``key`` at a mean root speed (m/s): linear between the joysticks around it by
    their *measured* mean speeds over the same episodes, the end values outside; None when the
    speed or the joysticks' speeds are missing."""
    return _read_line(line, "mean_speed_m_per_s", speed_m_per_s, key)


def against_line(result: Dict[str, Any], line: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
    """Where a policy's evaluation sits against the line: the line's IK-off sliding at the
    policy's time to target (the issue's reading), the policy's ratio to it, and whether it is
    at or below it; and the same at the policy's mean root speed (``..._at_speed``: the joysticks
    read by how fast they actually moved, which a joystick that circles before it reaches a
    target does not confuse with slowness)."""
    ours = result.get("foot_sliding_ik_off_cm_per_s")

    def ratio(ref):
        return None if ref is None or ours is None or ref <= 0 else float(ours / ref)

    ref = line_value(line, result.get("mean_time_to_target_s"))
    at_speed = line_value_at_speed(line, result.get("mean_speed_m_per_s"))
    return {"joystick_line": list(line), "joystick_line_sliding_ik_off_cm_per_s": ref,
            "sliding_ik_off_vs_joystick_line": ratio(ref),
            "at_or_below_joystick_line": None if ratio(ref) is None else bool(ours <= ref),
            "joystick_line_at_speed_sliding_ik_off_cm_per_s": at_speed,
            "sliding_ik_off_vs_joystick_line_at_speed": ratio(at_speed)}
