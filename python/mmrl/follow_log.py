"""The per-frame and per-step arrays of :func:`mmrl.rollout.follow` (a helper of its loop)."""
from __future__ import annotations

from typing import Any, Dict, List

import numpy as np

from . import metrics
from .motion.database import POSE_DIM, TRAJECTORY_DIM

#: Per-shown-frame keys of a controller recording (trimmed together; the reset pose first).
FRAME_KEYS = ("frames", "roots", "positions", "rotations", "local_translations", "local_rotations", "contacts",
              "lock_weights", "animated_feet")
#: Per-step keys of a controller recording.
STEP_KEYS = ("transitions", "queries", "costs")


class FollowLog:
    """The per-frame and per-step arrays of :func:`follow`."""

    def __init__(self, run):
        self.run = run
        self.episodes: List[Dict[str, np.ndarray]] = []
        self.outcomes: List[int] = []
        self.per_frame: Dict[str, list] = {"targets": []}
        self.per_step: Dict[str, list] = {"query_frames": [], "query_points": [], "query_directions": []}
        self.shown = 0  # frames of finished (cut) episodes
        self.start_episode()

    def frames_so_far(self) -> int:
        return self.shown + self.in_episode

    def start_episode(self) -> None:
        """A new episode's reset pose: one shown frame."""
        self.in_episode = 1
        self._frame_values({"targets": self.run.target[None]})
        if self.run.scene is not None:
            self._frame_values(self.run.scene.start_frame())

    def _frame_values(self, values: Dict[str, np.ndarray]) -> None:
        for key, value in values.items():
            self.per_frame.setdefault(key, []).append(np.asarray(value, np.float32))

    def add_step(self, out: Dict[str, Any], points: np.ndarray, directions: np.ndarray) -> None:
        self.per_step["query_frames"].append(self.frames_so_far() - 1)
        self.per_step["query_points"].append(points.astype(np.float32))
        self.per_step["query_directions"].append(directions.astype(np.float32))
        if self.run.compressed is not None:  # what the decision played: the projection or the continuation
            self.per_step.setdefault("match_features", []).append(
                self.run.env._core.compressed_chosen(0)[POSE_DIM:POSE_DIM + TRAJECTORY_DIM].astype(np.float32))
        for key, value in out.get("scene_step", {}).items():
            self.per_step.setdefault(key, []).append(value)
        # A continuous run shows the whole step; a cut one only up to the ending frame.
        shown = out["res"].frames.size if self.run.continuous else out["shown"]
        self._frame_values({"targets": np.repeat(out["target"][None], shown, 0)})
        self._frame_values(out.get("scene_frames", {}))
        self.in_episode += shown

    def end_episode(self, out: Dict[str, Any]) -> None:
        self.outcomes.append(1 if out["success"] else 3 if out["truncated"] else 2)
        if not self.run.continuous:
            self.episodes.append(self.run.last_recording)
            self.shown += self.in_episode
            self.in_episode = 0

    def result(self) -> Dict[str, Any]:
        run = self.run
        if self.in_episode > 1 or not self.episodes:  # the episode still running
            self.episodes.append(run.recording())
            self.outcomes.append(0)
        episodes = self.episodes
        rec: Dict[str, Any] = {}
        for k in FRAME_KEYS + STEP_KEYS:
            if k in episodes[0]:
                rec[k] = np.concatenate([e[k] for e in episodes])
        rec["fps"] = np.float32(run.db.fps)
        rec["frames_per_step"] = np.int32(run.config.frames_per_step)
        rec["episode"] = np.concatenate([np.full(e["frames"].size, i, np.int32) for i, e in enumerate(episodes)])
        for k, v in self.per_frame.items():
            rec[k] = np.concatenate(v)
        rec["frame_keys"] = tuple(self.per_frame)  # per-frame keys beyond the controller's: targets, the scene's
        for k, v in self.per_step.items():
            rec[k] = np.array(v)
        rec["outcomes"] = np.array(self.outcomes, np.int32)
        rec["stage"] = np.int32(run.stage or 0)
        if rec["targets"].shape[0] != rec["frames"].shape[0]:
            raise RuntimeError(f"follow: {rec['targets'].shape[0]} targets for {rec['frames'].shape[0]} frames")
        # Quality within episodes only (a cut between episodes is no pose jump).
        acc = metrics.QualityAccumulator()
        for e in episodes:
            acc.add(run.db, e)
        for key, value in acc.result().items():
            rec[key] = np.float32(np.nan if value is None else value)
        return rec
