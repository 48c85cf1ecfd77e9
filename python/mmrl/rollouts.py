"""Policies driving a full-path :class:`~mmrl.controller.Controller`: plane-task episodes with
quality metrics (``mmrl eval``), and target sequences for video and export. The fast-path
evaluation over the batched env is :func:`mmrl.evaluation.evaluate_plane`.

Episodes sample like the plane task (:class:`mmrl.envs.PlaneConfig`): a uniformly random
valid start frame at the origin, a uniform heading, a target uniform in the square
``[-h, h]^2`` at least ``min_target_distance`` away; success is reaching within
``success_radius`` on any played frame, before ``max_steps`` steps.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

import numpy as np

from .controller import Controller
from .database import Database
from .envs import PlaneConfig
from . import metrics


def sample_target(rng: np.random.Generator, config: PlaneConfig, origin=(0.0, 0.0)) -> np.ndarray:
    h = config.target_half_extent
    while True:
        t = rng.uniform(-h, h, size=2)
        if np.hypot(t[0], t[1]) >= config.min_target_distance:
            return t + np.asarray(origin, np.float64)


def _reached(roots: np.ndarray, target: np.ndarray, radius: float) -> int:
    """Index of the first played frame within radius of the target, or -1."""
    d2 = (roots[:, 0] - target[0]) ** 2 + (roots[:, 1] - target[1]) ** 2
    hit = np.flatnonzero(d2 <= radius * radius)
    return int(hit[0]) if hit.size else -1


def _quality(db: Database, rec: Dict[str, np.ndarray]) -> Dict[str, float]:
    feet = [db.joint_names.index(db.roles["left_foot"]), db.joint_names.index(db.roles["right_foot"])]
    return {
        "foot_sliding_cm_per_s": metrics.foot_sliding(rec["positions"], rec["contacts"], feet, db.fps),
        "max_pose_jump_cm": metrics.max_pose_jump(rec["positions"], rec["roots"], rec["frames"], db),
        "transitions_per_s": metrics.transitions_per_second(rec["transitions"], int(rec["frames_per_step"]), db.fps),
    }


class EpisodeSummary:
    """Collects evaluation episodes and their quality metrics into the JSON summary that
    ``mmrl eval`` prints (shared by the plane and obstacles tasks)."""

    def __init__(self, db: Database, step_time: float, fast: bool):
        self.db, self.step_time, self.fast = db, step_time, fast
        self.results: List[Dict[str, Any]] = []
        self.sliding_sum = self.sliding_w = self.jump = 0.0
        self.transitions = self.steps_total = 0

    def add(self, ep: Dict[str, Any], rec: Dict[str, np.ndarray], steps: int) -> None:
        """Adds one episode (``ep`` gets its quality metrics unless ``fast``)."""
        if not self.fast:
            q = _quality(self.db, rec)
            ep.update(q)
            n = rec["frames"].size
            self.sliding_sum += q["foot_sliding_cm_per_s"] * n
            self.sliding_w += n
            self.jump = max(self.jump, q["max_pose_jump_cm"])
        self.transitions += int(rec["transitions"].sum())
        self.steps_total += steps
        self.results.append(ep)

    def summary(self) -> Dict[str, Any]:
        results = self.results
        times = [e["time_to_target_s"] for e in results if e["success"]]
        return {
            "episodes": len(results),
            "success_rate": float(np.mean([e["success"] for e in results])),
            "mean_time_to_target_s": float(np.mean(times)) if times else None,
            "foot_sliding_cm_per_s": self.sliding_sum / self.sliding_w if self.sliding_w else None,
            "max_pose_jump_cm": self.jump if not self.fast else None,
            "transitions_per_s": (self.transitions / (self.steps_total * self.step_time)
                                  if self.steps_total else 0.0),
            "mean_steps": float(np.mean([e["steps"] for e in results])),
            "episode_results": results,
        }


def evaluate_full_path(db: Database, policy, *, episodes: int = 20, seed: int = 0,
                   config: Optional[PlaneConfig] = None, ik: bool = True, foot_locking: bool = True,
                   inertialization_halflife: float = 0.1, fast: bool = False,
                   target_distance: Optional[float] = None) -> Dict[str, Any]:
    """Run plane-task episodes with ``policy.act(obs[1, 17]) -> actions[1, 12]``.

    ``target_distance`` (meters) puts every target at that distance in a uniformly random
    direction instead of the task's square.

    Returns success_rate, mean_time_to_target_s (successful episodes), the quality metrics
    over all played frames (foot sliding and transitions averaged over episodes weighted by
    length, the pose jump a maximum), and per-episode details.
    """
    config = config or PlaneConfig()
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    rng = np.random.default_rng(seed)
    valid = np.flatnonzero(db.valid_mask)
    ctrl = Controller(db, frames_per_step=config.frames_per_step, inertialization_halflife=inertialization_halflife,
                      ik=ik, foot_locking=foot_locking, fast=fast, action_limit_std=config.action_limit_std,
                      record=True)
    step_time = config.frames_per_step / db.fps
    summary = EpisodeSummary(db, step_time, fast)
    for _ in range(episodes):
        start = int(rng.choice(valid))
        yaw = float(rng.uniform(-np.pi, np.pi)) if config.random_heading else 0.0
        if target_distance is None:
            target = sample_target(rng, config)
        else:
            a = rng.uniform(-np.pi, np.pi)
            target = float(target_distance) * np.array([np.sin(a), np.cos(a)])
        ctrl.reset(start, (0.0, 0.0), yaw)
        success, time_s = False, None
        for step in range(config.max_steps):
            action = np.asarray(policy.act(ctrl.observation(target)[None], deterministic=True), np.float32)
            res = ctrl.step(action.reshape(-1))
            k = _reached(res.roots, target, config.success_radius)
            if k >= 0:
                success, time_s = True, step * step_time + (k + 1) / db.fps
                break
        rec = ctrl.recording()
        ep = {"success": success, "time_to_target_s": time_s, "steps": ctrl.steps,
              "distance_m": float(np.hypot(*target))}
        summary.add(ep, rec, ctrl.steps)
    return summary.summary()


def follow_targets(db: Database, policy, *, seconds: float = 10.0, seed: int = 0,
                   config: Optional[PlaneConfig] = None, ik: bool = True, foot_locking: bool = True,
                   inertialization_halflife: float = 0.1) -> Dict[str, np.ndarray]:
    """Drive one character for ``seconds``: a new target (sampled around the character like the
    plane task's) whenever the current one is reached or max_steps pass.

    Returns the controller's recording plus ``targets`` (T, 2), the target of each shown frame,
    and ``query_points`` (S, 3, 2) / ``query_directions`` (S, 3, 2): each step's three future
    trajectory samples in world (x, z), and ``query_frames`` (S,) the shown-frame index at which
    each query was made.
    """
    config = config or PlaneConfig()
    rng = np.random.default_rng(seed)
    valid = np.flatnonzero(db.valid_mask)
    ctrl = Controller(db, frames_per_step=config.frames_per_step, inertialization_halflife=inertialization_halflife,
                      ik=ik, foot_locking=foot_locking, action_limit_std=config.action_limit_std, record=True)
    ctrl.reset(int(rng.choice(valid)), (0.0, 0.0), float(rng.uniform(-np.pi, np.pi)))
    target = sample_target(rng, config)
    targets = [target.copy()]
    qpts, qdirs, qframes = [], [], []
    steps = max(1, int(round(seconds * db.fps / config.frames_per_step)))
    since = 0
    for _ in range(steps):
        x, z, yaw = ctrl.root
        action = np.asarray(policy.act(ctrl.observation(target)[None], deterministic=True), np.float32).reshape(-1)
        # The query as asked (clipped like the env), in world space for drawing.
        raw = db.denormalize(np.concatenate([np.zeros(15, np.float32), action]))[15:].reshape(3, 4)
        c, s = np.cos(yaw), np.sin(yaw)
        rot = np.array([[c, s], [-s, c]])  # character (x, z) -> world (x, z)
        qpts.append(raw[:, :2] @ rot.T + np.array([x, z]))
        qdirs.append(raw[:, 2:] @ rot.T)
        qframes.append(len(targets) - 1)
        res = ctrl.step(action)
        since += 1
        k = _reached(res.roots, target, config.success_radius)
        for i in range(res.frames.size):
            targets.append(target.copy())
        if k >= 0 or since >= config.max_steps:
            target = sample_target(rng, config, origin=(res.roots[-1, 0], res.roots[-1, 1]))
            since = 0
    rec = ctrl.recording()
    rec["targets"] = np.array(targets, np.float32)
    rec["query_points"] = np.array(qpts, np.float32)
    rec["query_directions"] = np.array(qdirs, np.float32)
    rec["query_frames"] = np.array(qframes, np.int64)
    rec.update({k: np.float32(v) for k, v in _quality(db, rec).items()})
    return rec
