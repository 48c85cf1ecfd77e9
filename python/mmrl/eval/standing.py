"""Motion while standing (issue 38, docs/arrive.md): how still a controller stands once it has
arrived, next to the raw mocap's own idle frames.

For a task whose success is a rest (``Task.rests``: the arrive task), :func:`evaluate_standing`
runs full-path episodes and, after each success, lets the same controller play on for
``seconds`` at the same target and facing (the character keeps its pose and root: one
continuous motion). Over those frames it measures foot sliding with IK on and off, transitions
per second and pose jumps; at the moment the character stopped (the first frame of the hold
that made the success) it takes the largest pose jump within one decision either side.

Episode k starts from the env reseeded with ``seed`` and k, so every controller gets the same
episodes whatever happened before (a standing phase draws from the env's random stream).
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

import numpy as np

from .. import metrics
from ..motion.database import Database
from ..motion.kinds import idle_frames
from ..rollout import FRAME_KEYS, STEP_KEYS, FullPath, policy_actions
from ..tasks import Task

#: Seconds a controller plays on after each success (``mmrl eval --standing``'s default).
STANDING_SECONDS = 3.0


def _segment(rec: Dict[str, np.ndarray], first_step: int, frames_per_step: int) -> Dict[str, np.ndarray]:
    """The recording from step ``first_step`` on; its first frame is the one shown just before
    (the anchor of the first pair), as in a recording that starts with its reset pose."""
    a = first_step * frames_per_step
    out = {k: rec[k][a:] for k in FRAME_KEYS + ("natural_motion",) if k in rec}
    out.update({k: rec[k][first_step:] for k in STEP_KEYS if k in rec})
    return out


def stop_pose_jump(db: Database, rec: Dict[str, np.ndarray], stop: int, window: int) -> float:
    """The largest pose jump (cm) between the frames within ``window`` of shown frame ``stop``."""
    lo, hi = max(0, stop - window - 1), min(len(rec["frames"]), stop + window + 1)
    natural = rec.get("natural_motion")
    jumps = metrics.pose_jumps(rec["positions"][lo:hi], rec["roots"][lo:hi], rec["frames"][lo:hi], db,
                               natural=None if natural is None else natural[lo:hi - 1])
    return float(jumps.max()) if jumps.size else 0.0


def raw_idle_floor(db: Database) -> Dict[str, float]:
    """The raw-mocap floor (:func:`mmrl.metrics.raw_mocap_floor`) over the database's idle frames
    only: pairs of consecutive frames that both stand (:func:`mmrl.motion.kinds.idle_frames`)."""
    idle = idle_frames(db)
    pairs = idle.copy()
    pairs[1:] &= idle[:-1]
    pairs[0] = False
    return metrics.raw_mocap_floor(db, only=pairs)


def evaluate_standing(task: Task, db: Database, policy, *, episodes: int = 50, seconds: float = STANDING_SECONDS,
                      seed: int = 0, config=None, **options) -> Dict[str, Any]:
    """Full-path episodes of ``task`` and, after each success, ``seconds`` of play at the same
    target and facing (the module docstring). ``options``: :class:`~mmrl.rollout.FullPath`'s
    (``ik``, ``foot_locking``, ``inertialization_halflife``, ``request``, ``compressed``).

    Returns ``episodes``, ``stood`` (successful episodes, each with a standing phase),
    ``seconds``, the quality keys of :mod:`mmrl.metrics` pooled over the standing frames
    (``foot_sliding_cm_per_s``, ``foot_sliding_ik_off_cm_per_s``, ``transitions_per_s``,
    ``pose_jump_p99_cm``...), ``moved_cm`` (median distance the root moved while standing),
    ``stop_pose_jump_median_cm`` / ``_p95_cm`` / ``_max_cm`` (at the moment of stopping) and
    ``raw_idle`` (:func:`raw_idle_floor`) and ``episode_results`` (each episode's ``target``,
    ``facing``, ``success``, and after a success ``moved_cm`` and ``stop_pose_jump_cm``).
    """
    if int(episodes) < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if not (np.isfinite(seconds) and seconds > 0):
        raise ValueError(f"seconds must be positive, got {seconds!r}")
    if not task.rests:
        raise ValueError(f"the {task.name} task does not end at rest: nothing to measure while standing")
    run = FullPath(task, db, config=config, seed=seed, continuous=True, record=True, **options)
    per_step = run.config.frames_per_step
    hold = max(1, int(round(float(run.config.hold_time) * db.fps)))  # a resting task's config has hold_time
    quality = metrics.QualityAccumulator()
    stops: List[float] = []
    moved: List[float] = []
    results: List[Dict[str, Any]] = []
    steps_standing = max(1, int(np.ceil(seconds * db.fps / per_step)))
    for k in range(int(episodes)):
        obs, _ = run.env.reset(seed=int(seed) * 100_003 + k)
        run.obs = obs[0]
        run._start_episode()
        run.facing = None
        facing, target = float(run.env.env_state(0)["facing"]), run.target.copy()  # the episode's own
        steps = 0
        while True:
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            steps += 1
            if out["done"]:
                break
        results.append({"target": [float(target[0]), float(target[1])], "facing": facing, "success": out["success"]})
        if not out["success"]:
            continue
        end = (steps - 1) * per_step + out["step_frames"]  # shown frame that completed the hold
        for _ in range(steps_standing):
            if out["done"]:  # the success (or a rest again): play on at the same target and facing
                run.continue_from_character(target)
                run.set_facing(facing)
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
        rec = run.recording()
        standing = _segment(rec, steps, per_step)
        quality.add(db, standing)
        roots = np.asarray(standing["roots"], np.float64)
        moved.append(100.0 * float(np.hypot(*(roots[-1, :2] - roots[0, :2]))))
        stops.append(stop_pose_jump(db, rec, end - hold + 1, per_step))
        results[-1].update(moved_cm=moved[-1], stop_pose_jump_cm=stops[-1])
    out = {"episodes": int(episodes), "stood": len(stops), "seconds": float(steps_standing * per_step / db.fps)}
    out.update(quality.result())
    out.pop("matched_cost_mean", None)
    out["moved_cm"] = float(np.median(moved)) if moved else None
    for name, q in (("median", 50), ("p95", 95)):
        out[f"stop_pose_jump_{name}_cm"] = float(np.percentile(stops, q)) if stops else None
    out["stop_pose_jump_max_cm"] = float(np.max(stops)) if stops else None
    floor = raw_idle_floor(db)
    out["raw_idle"] = {"foot_sliding_cm_per_s": floor["foot_sliding_cm_per_s"], "frames": floor["frames"]}
    out["episode_results"] = results
    return out


def standing_line(res: Dict[str, Any]) -> Optional[str]:
    """``mmrl eval``'s line for a standing result (None when no episode stood)."""
    if not res.get("stood"):
        return None

    def f(v, d=1):
        return "n/a" if v is None else f"{v:.{d}f}"

    return (f"{res['stood']} of {res['episodes']} episodes, {res['seconds']:.1f} s after each success: foot sliding "
            f"{f(res['foot_sliding_cm_per_s'])} cm/s with IK, {f(res['foot_sliding_ik_off_cm_per_s'])} without "
            f"(raw mocap idle frames {f(res['raw_idle']['foot_sliding_cm_per_s'])}); "
            f"{f(res['transitions_per_s'], 2)} transitions per s; pose jump p99 {f(res['pose_jump_p99_cm'])} cm; "
            f"moved {f(res['moved_cm'])} cm (median); at the stop: pose jump median "
            f"{f(res['stop_pose_jump_median_cm'])} cm, p95 {f(res['stop_pose_jump_p95_cm'])}")


__all__ = ["STANDING_SECONDS", "evaluate_standing", "raw_idle_floor", "standing_line", "stop_pose_jump"]
