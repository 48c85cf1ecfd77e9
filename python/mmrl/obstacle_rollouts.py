"""Moving-obstacles episodes on the full-path character (``mmrl eval|render|export-bvh --env obstacles``).

A 1-env :class:`~mmrl.obstacles.ObstaclesVectorEnv` (the fast path: obstacles, sensors, hits,
collisions, success, termination) and a full-path :class:`~mmrl.controller.Controller` (poses,
IK, inertialization) are stepped side by side with the same start frame, root and actions.
Both take the same decisions (``controller.hpp``), so their roots agree and the env's
obstacles are exactly the ones the character walks through; :class:`ObstacleLockstep` checks
the agreement of frame and root after every step that did not end an episode.

Timing inside a step: the env moves its obstacles once per played frame and ends the step at
the first frame that succeeds or collides. The recording keeps the shown frames up to that
frame; obstacles between the env's per-step states are advanced with the env's own rule
(constant velocity, centres mirrored at the square's border), so at step boundaries they
are the env's exactly. Sensor maps and hit points are those of the decision (the step's
start), as the policy saw them.

Episodes run back to back in the one env (its autoreset draws the next start, target and
obstacles), so the same seed gives the same episodes for every policy.
"""
from __future__ import annotations

from typing import Any, Dict, List, Optional

import numpy as np

from .controller import Controller
from .database import Database
from .obstacles import Curriculum, ObstaclesConfig, ObstaclesVectorEnv


def stage_params(stage: int, num_stages: int = 10) -> tuple:
    """(obstacle max speed m/s, target half-extent m) of curriculum stage 1..num_stages."""
    return Curriculum(None, num_stages=num_stages).stage_params(stage)


def obstacle_corners(obst: Dict[str, np.ndarray], centres: Optional[np.ndarray] = None) -> np.ndarray:
    """(n, 4, 2) world (x, z) corners of the env's rectangles (``ObstaclesVectorEnv.obstacles``).

    A rectangle's frame is the world rotated by its angle about +Y (the yaw convention): a
    local point (u, v) is at world ``centre + (c u + s v, -s u + c v)``.
    """
    c = np.asarray(obst["centres"] if centres is None else centres, np.float64)
    h = np.asarray(obst["half_sizes"], np.float64)
    a = np.asarray(obst["angles"], np.float64)
    cos, sin = np.cos(a)[:, None], np.sin(a)[:, None]
    u = np.array([-1.0, 1.0, 1.0, -1.0])[None] * h[:, :1]
    v = np.array([-1.0, -1.0, 1.0, 1.0])[None] * h[:, 1:]
    return np.stack([c[:, :1] + cos * u + sin * v, c[:, 1:] - sin * u + cos * v], axis=-1)


def move_obstacles(centres: np.ndarray, velocities: np.ndarray, dt: float, square_half: float):
    """One frame of the env's obstacle motion (``ObstacleField::move``), float32 like the env."""
    h = np.float32(square_half)
    p = (centres + velocities * np.float32(dt)).astype(np.float32)
    v = velocities.copy()
    hi, lo = p > h, p < -h
    p = np.where(hi, 2 * h - p, np.where(lo, -2 * h - p, p)).astype(np.float32)
    v[hi | lo] = -v[hi | lo]
    return p, v


class ObstacleLockstep:
    """The env and the full-path controller stepped together (see the module docstring).

    Args:
        db: the database; config: the task's numbers; stage: curriculum stage 1..10 (None:
            the config's own stage); seed: the env's seed; controller options as
            :class:`~mmrl.controller.Controller`.
    """

    def __init__(self, db: Database, *, config: Optional[ObstaclesConfig] = None, stage: Optional[int] = 10,
                 seed: int = 0, ik: bool = True, foot_locking: bool = True, inertialization_halflife: float = 0.1,
                 fast: bool = False, record: bool = True):
        self.db = db
        self.env = ObstaclesVectorEnv(1, db=db, config=config, num_threads=1)
        self.config = self.env.config
        if stage is not None:
            self.env.set_stage(*stage_params(stage), label=stage)
        self.stage = stage
        self.ctrl = Controller(db, frames_per_step=self.config.frames_per_step,
                               inertialization_halflife=inertialization_halflife, ik=ik, foot_locking=foot_locking,
                               fast=fast, action_limit_std=self.config.action_limit_std, record=record)
        obs, _ = self.env.reset(seed=int(seed))
        self.obs = obs[0]
        self._start_episode()

    def _start_episode(self) -> None:
        s = self.env.env_state(0)
        self.ctrl.reset(int(s["frame"]), (float(s["x"]), float(s["z"])), float(s["yaw"]))
        self.target = np.array(s["target"], np.float64)
        self.episode_steps = 0

    def state(self) -> dict:
        return self.env.env_state(0)

    def step(self, action: np.ndarray) -> Dict[str, Any]:
        """One RL step of both. Returns the env's outcome, the controller's StepResult (``res``),
        the decision's sensor map / positions and hit points, the obstacles at the step's start,
        and ``shown``: how many of the step's frames were shown before the episode ended."""
        a = np.asarray(action, np.float32).reshape(1, -1)
        env = self.env
        before = {"sensor_map": env.sensor_map(0), "sensor_positions": env.sensor_positions(0),
                  "obstacles": env.obstacles(0), "target": self.target.copy()}
        hits, points, inside = env.action_hits(0, a[0])
        before.update(hits=int(hits), hit_points=np.asarray(points), hit_inside=np.asarray(inside, bool))
        obs, reward, term, trunc, info = env.step(a)
        res = self.ctrl.step(a[0])
        self.episode_steps += 1
        done = bool(term[0] or trunc[0])
        out = dict(before, res=res, reward=float(reward[0]), terminated=bool(term[0]), truncated=bool(trunc[0]),
                   done=done, shown=res.frames.size, success=False, collision=False)
        if done:
            # The episode's last root is the one whose goal vector the final observation holds.
            g = info["final_obs"][0, -2:].astype(np.float64)
            x, z, yaw = res.roots[:, 0], res.roots[:, 1], res.roots[:, 2]
            dx, dz = self.target[0] - x, self.target[1] - z
            c, s = np.cos(yaw), np.sin(yaw)
            local = np.stack([c * dx - s * dz, s * dx + c * dz], 1)
            out["shown"] = int(np.argmin(np.linalg.norm(local - g, axis=1))) + 1 if term[0] else res.frames.size
            out["goal_error"] = float(np.min(np.linalg.norm(local - g, axis=1)))
            out.update(success=bool(info["success"][0]), collision=bool(info["collision"][0]),
                       episode_length=int(info["episode_length"][0]), episode_return=float(info["episode_return"][0]))
            if self.ctrl._record:
                self.last_recording = self.recording(trim=res.frames.size - out["shown"])
            self.obs = obs[0]
            self._start_episode()
        else:
            self.obs = obs[0]
        return out

    def recording(self, trim: int = 0) -> Dict[str, np.ndarray]:
        """The controller's recording of the current episode without its last ``trim`` shown frames."""
        rec = self.ctrl.recording()
        if trim:
            for k in ("frames", "roots", "positions", "rotations", "local_translations", "local_rotations",
                      "contacts", "lock_weights"):
                if k in rec:
                    rec[k] = rec[k][:-trim]
        return rec

    def root_error(self) -> tuple:
        """(|frame difference|, max |root difference|) between the env and the controller now."""
        s = self.env.env_state(0)
        d = np.abs(np.array([s["x"], s["z"]]) - np.array(self.ctrl.root[:2]))
        dyaw = abs((s["yaw"] - self.ctrl.root[2] + np.pi) % (2 * np.pi) - np.pi)
        return abs(int(s["frame"]) - self.ctrl.frame), float(max(d.max(), dyaw))


def _act(policy, obs: np.ndarray) -> np.ndarray:
    return np.asarray(policy.act(obs[None], deterministic=True), np.float32).reshape(-1)


def evaluate_obstacles(db: Database, policy, *, episodes: int = 20, seed: int = 0,
                       config: Optional[ObstaclesConfig] = None, stage: Optional[int] = 10, ik: bool = True,
                       foot_locking: bool = True, inertialization_halflife: float = 0.1,
                       fast: bool = False) -> Dict[str, Any]:
    """Run moving-obstacles episodes with ``policy.act(obs[1, 529]) -> actions[1, 12]``.

    Each episode ends on success, collision or the safety cap (``max_steps``). Returns the
    keys of :func:`mmrl.rollouts.evaluate_full_path` plus ``collision_rate``, ``truncation_rate``
    and ``stage``.
    """
    from .rollouts import EpisodeSummary

    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    run = ObstacleLockstep(db, config=config, stage=stage, seed=seed, ik=ik, foot_locking=foot_locking,
                           inertialization_halflife=inertialization_halflife, fast=fast, record=True)
    cfg = run.config
    step_time = cfg.frames_per_step / db.fps
    summary = EpisodeSummary(db, step_time, fast)
    for _ in range(episodes):
        distance = float(np.hypot(*(run.target - np.array(run.ctrl.root[:2]))))
        while True:
            out = run.step(_act(policy, run.obs))
            if out["done"]:
                break
        # The recording covers the episode (the next one's reset has not been recorded yet:
        # _start_episode reset the controller, so read the episode from the step results).
        ep = {"success": out["success"], "collision": out["collision"], "truncated": out["truncated"],
              "steps": out["episode_length"], "distance_m": distance,
              "time_to_target_s": ((out["episode_length"] - 1) * step_time + out["shown"] / db.fps)
              if out["success"] else None}
        summary.add(ep, run.last_recording, out["episode_length"])
    results = summary.results
    out = summary.summary()
    out.update({
        "collision_rate": float(np.mean([e["collision"] for e in results])),
        "truncation_rate": float(np.mean([e["truncated"] for e in results])),
        "stage": stage,
    })
    out["episode_results"] = out.pop("episode_results")  # keep the per-episode list last
    return out


def follow_obstacles(db: Database, policy, *, seconds: float = 10.0, seed: int = 0,
                     config: Optional[ObstaclesConfig] = None, stage: Optional[int] = 10, ik: bool = True,
                     foot_locking: bool = True, inertialization_halflife: float = 0.1) -> Dict[str, np.ndarray]:
    """Drive the character through moving-obstacles episodes for ``seconds`` of shown frames.

    Episodes follow each other (a cut at each new start). Returns, per shown frame (T): the
    controller's recording keys (``positions``, ``roots``, ``frames``, ...), ``targets`` (T, 2),
    ``obstacles`` (T, n, 4, 2) world corners, ``episode`` (T,) episode index; per step (S):
    ``query_frames`` (S,) the shown-frame index at which each decision was made,
    ``query_points`` (S, 3, 2) the action's three positions (the hit points) and
    ``query_directions`` (S, 3, 2), ``hit_inside`` (S, 3), ``sensor_maps`` (S, 16, 16) and
    ``sensor_positions`` (S, 16, 16, 2); ``outcomes`` (E,) 0 running, 1 success, 2 collision,
    3 truncated.
    """
    from .rollouts import _quality

    if not seconds > 0:
        raise ValueError(f"seconds must be positive, got {seconds!r}")
    run = ObstacleLockstep(db, config=config, stage=stage, seed=seed, ik=ik, foot_locking=foot_locking,
                           inertialization_halflife=inertialization_halflife, record=True)
    cfg = run.config
    total = max(2, int(round(seconds * db.fps)))
    episodes: List[Dict[str, np.ndarray]] = []
    per_frame: Dict[str, list] = {"targets": [], "obstacles": []}
    per_step: Dict[str, list] = {k: [] for k in ("query_frames", "query_points", "query_directions", "hit_inside",
                                                 "sensor_maps", "sensor_positions")}
    outcomes: List[int] = []
    shown = 0  # frames of finished episodes
    in_episode = 1  # frames of the current episode, its reset pose included

    def start_frames():
        o = run.env.obstacles(0)
        per_frame["obstacles"].append(obstacle_corners(o)[None].astype(np.float32))
        per_frame["targets"].append(run.target[None].astype(np.float32))

    start_frames()
    while shown + in_episode < total:
        x, z, yaw = run.ctrl.root
        action = _act(policy, run.obs)
        raw = db.denormalize(np.concatenate([np.zeros(15, np.float32), np.clip(
            action, run.env.single_action_space.low, run.env.single_action_space.high)]))[15:].reshape(3, 4)
        c, s = np.cos(yaw), np.sin(yaw)
        out = run.step(action)
        per_step["query_frames"].append(shown + in_episode - 1)
        per_step["query_points"].append(out["hit_points"].astype(np.float32))
        per_step["query_directions"].append((raw[:, 2:] @ np.array([[c, s], [-s, c]]).T).astype(np.float32))
        per_step["hit_inside"].append(out["hit_inside"])
        per_step["sensor_maps"].append(out["sensor_map"])
        per_step["sensor_positions"].append(out["sensor_positions"].astype(np.float32))
        o = out["obstacles"]
        p, v = o["centres"].astype(np.float32), o["velocities"].astype(np.float32)
        corners = []
        for _ in range(out["shown"]):  # static obstacles have zero velocities: no motion either way
            p, v = move_obstacles(p, v, 1.0 / db.fps, cfg.obstacle_square_half)
            corners.append(obstacle_corners(o, p))
        per_frame["obstacles"].append(np.array(corners, np.float32))
        per_frame["targets"].append(np.repeat(out["target"][None], out["shown"], 0).astype(np.float32))
        in_episode += out["shown"]
        if out["done"]:
            episodes.append(run.last_recording)
            outcomes.append(1 if out["success"] else 2 if out["collision"] else 3)
            shown += in_episode
            in_episode = 1
            if shown + in_episode < total:
                start_frames()
    if in_episode > 1:  # the episode still running
        episodes.append(run.recording())
        outcomes.append(0)
    rec: Dict[str, Any] = {}
    for k in ("frames", "roots", "positions", "rotations", "local_translations", "local_rotations", "contacts",
              "lock_weights"):
        rec[k] = np.concatenate([e[k] for e in episodes])
    rec["transitions"] = np.concatenate([e["transitions"] for e in episodes])
    rec["queries"] = np.concatenate([e["queries"] for e in episodes])
    rec["fps"] = np.float32(db.fps)
    rec["frames_per_step"] = np.int32(cfg.frames_per_step)
    rec["episode"] = np.concatenate([np.full(e["frames"].size, i, np.int32) for i, e in enumerate(episodes)])
    rec["targets"] = np.concatenate(per_frame["targets"])
    rec["obstacles"] = np.concatenate(per_frame["obstacles"])
    for k, v in per_step.items():
        rec[k] = np.array(v)
    rec["outcomes"] = np.array(outcomes, np.int32)
    rec["stage"] = np.int32(stage or 0)
    assert rec["targets"].shape[0] == rec["frames"].shape[0] == rec["obstacles"].shape[0]
    # Quality metrics within episodes only (the cut between episodes is no pose jump).
    q = [_quality(db, e) for e in episodes]
    n = np.array([e["frames"].size for e in episodes], np.float64)
    rec["foot_sliding_cm_per_s"] = np.float32(np.dot([v["foot_sliding_cm_per_s"] for v in q], n) / n.sum())
    rec["max_pose_jump_cm"] = np.float32(max(v["max_pose_jump_cm"] for v in q))
    return rec
