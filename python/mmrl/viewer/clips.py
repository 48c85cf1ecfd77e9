"""What ``mmrl view`` and ``mmrl render --html`` play back: a :class:`Playback` from a run
directory, a BVH file or a database ``.npz``.

- a **run**: the run's policy follows its task on the full path (:func:`mmrl.rollout.follow`,
  as ``mmrl render`` does); the clips are its episodes, with targets, obstacles, sensor
  maps, the policy's trajectory points and the matched frame's, and foot contacts;
- a **BVH file**: the file's motion (one clip);
- a **database** (``mmrl db build``): its clips, played straight, with foot contacts.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from ..errors import InputError


@dataclass
class Playback:
    """Frames to play: ``recording`` holds per-frame ``positions`` (T, J, 3) world meters and
    optionally the keys of :func:`mmrl.viz.render.recording_frame` plus ``contacts`` (T, 2) and
    per decision ``match_points`` / ``match_directions`` (S, 3, 2)."""

    name: str
    parents: np.ndarray
    joint_names: List[str]
    fps: float
    recording: Dict[str, Any]
    clips: List[Tuple[str, int, int]]
    """(name, first frame, end frame) ranges into the recording."""
    body_joints: Optional[np.ndarray] = None
    feet: Optional[List[int]] = None
    success_radius: float = 0.5
    info: Dict[str, Any] = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.recording["positions"].shape[0])

    def decision_at(self, t: int) -> int:
        """Index of the last decision made at or before frame t (-1 before the first)."""
        q = self.recording.get("query_frames")
        return -1 if q is None else int(np.searchsorted(q, t, side="right")) - 1

    def frame(self, t: int) -> Dict[str, Any]:
        """What frame t shows (see :func:`mmrl.viz.render.recording_frame`)."""
        from ..viz.render import recording_frame

        rec = self.recording
        if "query_frames" in rec:
            q = self.decision_at(t)
            shown = recording_frame(rec, t, q)
            has_q = shown["query_points"] is not None
            if "match_points" in rec:
                shown["match_points"] = rec["match_points"][q] if has_q else None
                shown["match_directions"] = rec["match_directions"][q] if has_q else None
        else:
            shown = {"positions": rec["positions"][t]}
        if "contacts" in rec:
            shown["contacts"] = rec["contacts"][t]
        return shown

    def ground_path(self, start: int, end: int) -> np.ndarray:
        """(T, 2) world (x, z) of the character over frames [start, end): the root when recorded,
        else the body's mean."""
        rec = self.recording
        if "roots" in rec:
            return np.asarray(rec["roots"][start:end, :2], np.float64)
        body = self.body_joints if self.body_joints is not None else np.arange(len(self.parents))
        return np.asarray(rec["positions"][start:end][:, body][..., [0, 2]].mean(1), np.float64)


def load_playback(source: str, *, seconds: float = 20.0, seed: int = 0, stage: Optional[int] = None) -> Playback:
    """A run directory, a ``.bvh`` file or a database ``.npz`` (see the module docstring)."""
    path = Path(source)
    if path.is_dir():
        return run_playback(path, seconds=seconds, seed=seed, stage=stage)
    if not path.exists():
        raise InputError(f"{path}: no such run directory, BVH file or database")
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return bvh_playback(path)
    if suffix == ".npz":
        return database_playback(path)
    raise InputError(f"{path}: expected a run directory, a .bvh file or a database .npz")


def bvh_playback(path: Path) -> Playback:
    from ..motion.bvh import load_bvh

    motion = load_bvh(path)
    positions = np.asarray(motion.global_positions(), np.float32)
    return Playback(name=path.name, parents=np.asarray(motion.parents, np.int64), joint_names=list(motion.joint_names),
                    fps=float(motion.fps), recording={"positions": positions},
                    clips=[(path.name, 0, positions.shape[0])])


def database_playback(path: Path) -> Playback:
    from .. import _core
    from ..motion.database import Database
    from ..metrics import body_joints, feet

    db = Database.load(path)
    frames = np.arange(db.num_frames, dtype=np.int64)
    positions = np.asarray(_core.database_global_positions(db._db, frames), np.float32)
    names = db.clip_names
    clips = [(_short(names[i]) if i < len(names) else f"clip {i + 1}", int(a), int(b))
             for i, (a, b) in enumerate(np.asarray(db.clip_ranges).reshape(-1, 2))]
    return Playback(name=path.name, parents=np.asarray(db.parents, np.int64), joint_names=list(db.joint_names),
                    fps=float(db.fps), recording={"positions": positions, "contacts": np.asarray(db.contacts, bool)},
                    clips=clips, body_joints=body_joints(db), feet=feet(db))


def _short(name: str) -> str:
    """A clip's file as its folder and name (``walk/clip_001.bvh``), short enough for a menu."""
    p = Path(str(name))
    return f"{p.parent.name}/{p.name}" if p.parent.name else p.name


def run_playback(path: Path, *, seconds: float = 20.0, seed: int = 0, stage: Optional[int] = None) -> Playback:
    """The run's policy on its task for ``seconds`` of shown motion (episodes cut as in ``mmrl render``)."""
    from ..rollout import follow
    from ..runs import RunDir

    if not seconds > 0:
        raise InputError("--length must be positive")
    run = RunDir(path, require_run=True)
    task = run.task
    if stage is not None and not 1 <= stage <= (task.stages or 0):
        raise InputError(f"--stage must be in 1..{task.stages} for a {task.name} run" if task.stages
                         else f"--stage: the {task.name} task has no curriculum stages")
    config = run.task_config(task)
    db = run.database()
    rec = follow(task, db, run.policy(), seconds=seconds, seed=seed, config=config, stage=stage)
    return recording_playback(f"{path.name} ({task.name})", db, rec, task, config)


def recording_playback(name: str, db, rec: Dict[str, Any], task, config) -> Playback:
    """A :func:`mmrl.rollout.follow` recording as a Playback whose clips are its episodes."""
    from ..metrics import body_joints, feet

    add_matched_queries(db, rec)
    episode = np.asarray(rec["episode"])
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]])
    ends = np.r_[starts[1:], len(episode)]
    clips = [(f"episode {int(episode[a]) + 1}", int(a), int(b)) for a, b in zip(starts, ends)]
    return Playback(name=name, parents=np.asarray(db.parents, np.int64), joint_names=list(db.joint_names),
                    fps=float(db.fps), recording=rec, clips=clips, body_joints=body_joints(db), feet=feet(db),
                    success_radius=float(getattr(config, "success_radius", 0.5)),
                    info={"task": task.name, "outcomes": np.asarray(rec["outcomes"]).tolist()})


def add_matched_queries(db, rec: Dict[str, Any]) -> None:
    """Per decision, the chosen motion's own three future points and directions (S, 3, 2)
    placed at the decision's root: what the match offered next to what the policy asked
    (``match_features``: the chosen trajectory's normalized features, whatever the source)."""
    from ..rollout import _world_query

    qf = np.asarray(rec["query_frames"], np.int64)
    roots = np.asarray(rec["roots"], np.float64)
    chosen = np.asarray(rec["match_features"], np.float32)
    pts, dirs = [], []
    for q, m in enumerate(chosen):
        p, d = _world_query(db, m, roots[qf[q]])
        pts.append(p)
        dirs.append(d)
    rec["match_points"] = np.array(pts, np.float32).reshape(-1, 3, 2)
    rec["match_directions"] = np.array(dirs, np.float32).reshape(-1, 3, 2)
