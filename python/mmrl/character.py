"""The motion-matching character (C++ ``Character``, see cpp/include/mmrl/character.hpp).

Each :meth:`Character.step` takes the 12-d trajectory half of a query (the same normalized
units as the plane task's action) and decides with the one decision engine every path uses
(C++ ``Decider`` over the database, cpp/include/mmrl/decider.hpp): the full query is the
current frame's pose features and the trajectory, matched under the transition cost and clip
costs; the C++ ``Character`` then plays ``frames_per_step`` frames of the decision:

- decision rule: the current frame is the starting best, so playback simply continues
  unless another valid frame is strictly closer (a *transition*);
- root motion: the played frames' database root deltas accumulate in world space;
- the trajectory is clipped to the same box as the env action (``action_limit_std``).

The full path also returns world-space poses of every played frame, inertialized at
transitions, with planted feet locked by a two-bone leg IK. ``fast=True`` computes the root
only (what training uses); both paths take the same decisions and root trajectory.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _core
from .arrays import real_array
from .motion.clip_costs import clip_cost_array
from .motion.database import POSE_DIM, TRAJECTORY_DIM, Database


@dataclass
class StepResult:
    """What one controller step played (F = frames_per_step, J joints; world space, meters)."""

    frames: np.ndarray
    """(F,) database frames shown."""
    roots: np.ndarray
    """(F, 3) world root (x, z, yaw in radians) of each shown frame."""
    positions: Optional[np.ndarray]
    """(F, J, 3) global joint positions (None on the fast path)."""
    rotations: Optional[np.ndarray]
    """(F, J, 4) global joint rotations, unit quaternions (w, x, y, z)."""
    local_translations: Optional[np.ndarray]
    """(F, J, 3) BVH-style local translations (root joints placed in the world)."""
    local_rotations: Optional[np.ndarray]
    """(F, J, 4) local rotations (w, x, y, z)."""
    contacts: np.ndarray
    """(F, 2) bool: the database's left/right foot contacts of the shown frames."""
    lock_weights: np.ndarray
    """(F, 2) foot-lock blend weights (0 = animated, 1 = locked)."""
    match: int
    """The frame chosen by the match (the shown frames are match + 1 .. match + F)."""
    transition: bool
    """True when the match was not the current frame's continuation."""
    cost: float
    """Squared distance of the match in the normalized, weighted feature space."""
    animated_feet: Optional[np.ndarray] = None
    """(F, 2, 3) world positions of the left/right ankle before foot locking and IK (None on
    the fast path): the ankles of the same run with IK off, since IK changes nothing later."""


def _anchor(anchor) -> tuple:
    """A decision's anchor (dx, dz) as two finite floats (ValueError otherwise)."""
    a = real_array(anchor, "anchor", (2,), dtype=np.float64, finite=True)
    return float(a[0]), float(a[1])


def _query_or_zeros(trajectory_query: Optional[np.ndarray]) -> np.ndarray:
    """A decision's (12,) trajectory query as recorded; zeros when none is given."""
    if trajectory_query is None:
        return np.zeros(TRAJECTORY_DIM, np.float32)
    return np.asarray(trajectory_query, np.float32).reshape(TRAJECTORY_DIM)


class Character:
    """A character driven by motion matching.

    Args:
        db: the motion database.
        frames_per_step: frames played per step (6 = 0.2 s at 30 fps).
        inertialization_halflife: seconds; 0 or None switches hard at transitions.
        ik: two-bone leg IK; foot_locking: lock planted feet (needs ``ik``).
        start_frame: database frame to start on (default: the first valid frame).
        position: world (x, z) of the root, meters; yaw: heading in radians (forward = (sin, 0, cos)).
        fast: root motion only (no poses), the training path.
        action_limit_std: trajectories are clipped to mean +- this many std per dimension,
            like the env's action box (0 or None: no clipping).
        transition_cost: transition cost of the match (squared normalized distance; 0 is
            the paper's rule), like the task option of the same name.
        clip_costs: the decision's clip-cost filter, like the task option of the same name
            (``"PATTERN=COST;..."``, see :func:`clip_cost_array`).
        foot_jump_limit: a match refuses frames whose feet stand farther than this (meters)
            from the shown frame's, like the task option of the same name (0: off).
        record: keep every shown frame for :meth:`recording` (metrics, video, export).
    """

    def __init__(self, db: Database, *, frames_per_step: int = 6, inertialization_halflife: Optional[float] = 0.1,
                 ik: bool = True, foot_locking: bool = True, start_frame: Optional[int] = None,
                 position: Sequence[float] = (0.0, 0.0), yaw: float = 0.0, fast: bool = False,
                 action_limit_std: Optional[float] = 3.0, record: bool = False, transition_cost: float = 0.0,
                 clip_costs: str = "", foot_jump_limit: float = 0.0):
        if not isinstance(db, Database):
            raise TypeError(f"db: expected an mmrl.Database, got {type(db).__name__}")
        if not isinstance(frames_per_step, (int, np.integer)) or not 1 <= frames_per_step <= _core.MAX_FRAMES_PER_STEP:
            raise ValueError(f"frames_per_step must be an int between 1 and {_core.MAX_FRAMES_PER_STEP}, "
                             f"got {frames_per_step!r}")
        halflife = float(inertialization_halflife or 0.0)
        if not np.isfinite(halflife) or halflife < 0:
            raise ValueError(f"inertialization_halflife must be >= 0 seconds, got {inertialization_halflife!r}")
        limit = float(action_limit_std or 0.0)
        if not np.isfinite(limit) or limit < 0:
            raise ValueError(f"action_limit_std must be >= 0, got {action_limit_std!r}")
        opt = _core.CharacterOptions()
        opt.frames_per_step = int(frames_per_step)
        opt.poses = not fast
        opt.inertialization_halflife = halflife
        opt.ik = bool(ik)
        opt.foot_locking = bool(foot_locking)
        if not np.isfinite(float(transition_cost)) or float(transition_cost) < 0:
            raise ValueError(f"transition_cost must be finite and >= 0, got {transition_cost!r}")
        costs = clip_cost_array(clip_costs, db).tolist() if clip_costs else []
        self.db = db
        self.fast = bool(fast)
        self.frames_per_step = int(frames_per_step)
        self._decider = _core.Decider(db._db, db.matcher, limit, float(transition_cost), costs, float(foot_jump_limit))
        self._core = _core.Character(db._db, opt)
        self._record = bool(record)
        self._rec: Dict[str, List[np.ndarray]] = {}
        self.reset(start_frame, position, yaw)

    @property
    def transition_cost(self) -> float:
        """The transition cost of the next matches; settable between steps (a task may vary
        it per decision)."""
        return float(self._decider.transition_cost)

    @transition_cost.setter
    def transition_cost(self, cost: float) -> None:
        try:
            value = float(cost)
        except (TypeError, ValueError):
            value = float("nan")
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"transition_cost must be finite and >= 0, got {cost!r}")
        self._decider.transition_cost = value

    # ------------------------------------------------------------------ state
    def reset(self, start_frame: Optional[int] = None, position: Sequence[float] = (0.0, 0.0),
              yaw: float = 0.0) -> None:
        """Put the character on ``start_frame`` at ``position`` (x, z) facing ``yaw``."""
        if start_frame is None:
            start_frame = int(np.flatnonzero(self.db.valid_mask)[0])
        if not isinstance(start_frame, (int, np.integer)) or isinstance(start_frame, bool):
            raise TypeError(f"start_frame: expected an int, got {type(start_frame).__name__}")
        if not 0 <= start_frame < self.db.num_frames:
            raise ValueError(f"start_frame {start_frame} is out of range [0, {self.db.num_frames})")
        pos = real_array(position, "position", (2,), dtype=np.float64)
        if not np.isfinite(pos).all():
            raise ValueError(f"position: expected finite (x, z), got {position!r}")
        if not np.isfinite(float(yaw)):
            raise ValueError(f"yaw must be finite, got {yaw!r}")
        self._core.reset(int(start_frame), float(pos[0]), float(pos[1]), float(yaw))
        self.reset_common()

    def reset_common(self) -> None:
        """After a core reset: clears the counters and starts the recording with the pose shown."""
        self.transitions = 0
        self.steps = 0
        if self._record:
            self._rec = {k: [] for k in ("frames", "roots", "positions", "rotations", "local_translations",
                                         "local_rotations", "contacts", "lock_weights", "animated_feet")}
            self._rec["frames"].append(np.array([self.frame], np.int64))
            self._rec["roots"].append(np.array([self.root], np.float32))
            self._rec["contacts"].append(np.zeros((1, 2), bool) if self.frame < 0 else  # reset_row sets its own
                                         self.db.contacts[self.frame][None].copy())
            self._rec["lock_weights"].append(np.array(self._core.current_lock_weights())[None])
            if not self.fast:
                for key, arr in zip(("positions", "rotations", "local_translations", "local_rotations"),
                                    self._core.current_pose()):
                    self._rec[key].append(np.array(arr)[None])
                self._rec["animated_feet"].append(np.array(self._core.current_animated_feet())[None])
            self._rec["transitions"] = []
            self._rec["queries"] = []
            self._rec["costs"] = []

    @property
    def root(self) -> Tuple[float, float, float]:
        """World root (x, z, yaw)."""
        return tuple(float(v) for v in self._core.root)

    @property
    def frame(self) -> int:
        """The database frame shown now."""
        return int(self._core.frame)

    def pose(self) -> Tuple[np.ndarray, np.ndarray]:
        """Global positions (J, 3) and rotations (J, 4) of the pose shown now (full path)."""
        gp, gr, _, _ = self._core.current_pose()
        return np.array(gp), np.array(gr)

    #: The segments of :meth:`observation` (the plane task's), for a policy that reads them by name
    #: (``JoystickPolicy(db, layout=Character.observation_layout)``).
    observation_layout = (("pose", POSE_DIM), ("goal", 2))

    def observation(self, target: Sequence[float]) -> np.ndarray:
        """The plane task's observation (17,) for a world target (x, z): pose features + target in the character frame.
        ValueError for a character that shows no database frame (a compressed controller's rows:
        its pose features are the env's, ``env.observe``)."""
        target = real_array(target, "target", (2,), dtype=np.float64, finite=True)
        if self.frame < 0:
            raise ValueError("observation: this character shows a compressed controller's rows, not a database "
                             "frame; read the observation from the env that decides for it")
        x, z, yaw = self.root
        dx, dz = float(target[0]) - x, float(target[1]) - z
        c, s = np.cos(yaw), np.sin(yaw)
        obs = np.empty(POSE_DIM + 2, np.float32)
        obs[:POSE_DIM] = self.db.normalized_features[self.frame, :POSE_DIM]
        obs[POSE_DIM] = c * dx - s * dz
        obs[POSE_DIM + 1] = s * dx + c * dz
        return obs

    # ------------------------------------------------------------------ step
    def step(self, trajectory_query) -> StepResult:
        """Match with a 12-d normalized trajectory query and play ``frames_per_step`` frames."""
        q = trajectory_query
        if not isinstance(q, np.ndarray):
            raise TypeError(f"trajectory_query: expected a numpy array, got {type(q).__name__}")
        if not np.issubdtype(q.dtype, np.floating):
            raise TypeError(f"trajectory_query: expected a float array, got dtype {q.dtype}")
        if q.shape != (TRAJECTORY_DIM,):
            raise ValueError(f"trajectory_query: expected shape ({TRAJECTORY_DIM},), got {q.shape}")
        q = np.ascontiguousarray(q, dtype=np.float32)
        if not np.isfinite(q).all():
            raise ValueError("trajectory_query: contains NaN or inf")
        if self.frame < 0:
            raise ValueError("step: this character plays a compressed controller's rows (play_rows), not the database")
        match, cost = self._decider.decide(self.frame, q)
        self._core.play(int(match), float(cost))
        return self._played(q)

    def play(self, match: int, cost: float, trajectory_query: Optional[np.ndarray] = None,
             anchor: Sequence[float] = (0.0, 0.0)) -> StepResult:
        """Play a decision made elsewhere: frames ``match + 1 .. match + frames_per_step``, with
        the transition, root motion and poses of :meth:`step`. The full path plays the vector
        env's decision this way (``env.last_step_match``), so it never decides a second time.
        ``trajectory_query`` (12,) is only recorded (``recording()["queries"]``); ``anchor``
        (dx, dz) is the decision's root move that keeps the planted feet at a transition
        (``env.last_step_anchor``; the arrive task's ``stand_anchor``)."""
        if not isinstance(match, (int, np.integer)) or isinstance(match, bool):
            raise TypeError(f"match: expected an int frame, got {type(match).__name__}")
        if not (0 <= int(match) < self.db.num_frames and self.db.valid_mask[int(match)]):
            raise ValueError(f"match: frame {match} is not a valid match frame of the database")
        q = _query_or_zeros(trajectory_query)
        self._core.play(int(match), float(cost), _anchor(anchor))
        return self._played(q)

    # ------------------------------------------------------------------ compressed controllers
    def reset_row(self, row: np.ndarray, position: Sequence[float] = (0.0, 0.0), yaw: float = 0.0) -> None:
        """Start on a compressed controller's pose row (9 J + 5, mmrl.compress.pose) at
        ``position`` facing ``yaw``; :attr:`frame` is -1 from now on (no database frame is shown).
        Recordings then carry ``natural_motion`` (the decoded animation's own motion per shown
        frame), which the pose-jump metric reads instead of the database's."""
        row = np.ascontiguousarray(real_array(row, "row", (9 * self.db.num_joints + 5,), dtype=np.float32))
        pos = real_array(position, "position", (2,), dtype=np.float64, finite=True)
        if not np.isfinite(float(yaw)):
            raise ValueError(f"yaw must be finite, got {yaw!r}")
        self._core.reset_row(row, float(pos[0]), float(pos[1]), float(yaw))
        self.reset_common()
        if self._record:
            J = self.db.num_joints
            self._rec["contacts"][0] = (row[9 * J + 3:9 * J + 5] > 0.5)[None]
            self._rec["natural_motion"] = []

    def play_rows(self, rows: np.ndarray, transition: bool, cost: float,
                  trajectory_query: Optional[np.ndarray] = None, anchor: Sequence[float] = (0.0, 0.0)) -> StepResult:
        """Play a compressed controller's decision: its pose rows (frames_per_step + 1, 9 J + 5),
        the env's ``compressed_rows`` (row 0 the chosen state's pose, rows 1.. shown); ``anchor``
        as in :meth:`play`."""
        rows = np.ascontiguousarray(real_array(rows, "rows", (self.frames_per_step + 1, 9 * self.db.num_joints + 5),
                                               dtype=np.float32))
        q = _query_or_zeros(trajectory_query)
        self._core.play_rows(rows, bool(transition), float(cost), _anchor(anchor))
        if self._record and not self.fast:
            from .compress.model import natural_motion

            self._rec.setdefault("natural_motion", []).append(natural_motion(rows, self.db.parents))
        return self._played(q)

    def _played(self, q: np.ndarray) -> StepResult:
        c = self._core
        self.steps += 1
        self.transitions += int(c.last_transition)
        poses = (None,) * 4 if self.fast else tuple(np.array(a) for a in c.poses())
        res = StepResult(frames=c.played_frames, roots=np.array(c.roots), positions=poses[0], rotations=poses[1],
                         local_translations=poses[2], local_rotations=poses[3],
                         contacts=np.array(c.contacts).astype(bool), lock_weights=np.array(c.lock_weights),
                         match=int(c.last_match), transition=bool(c.last_transition), cost=float(c.last_cost),
                         animated_feet=None if self.fast else np.array(c.animated_feet()))
        if self._record:
            r = self._rec
            r["transitions"].append(res.transition)
            r["queries"].append(q.copy())
            r["costs"].append(res.cost)
            pose_keys = () if self.fast else ("positions", "rotations", "local_translations", "local_rotations",
                                              "animated_feet")
            for key in ("frames", "roots", "contacts", "lock_weights") + pose_keys:
                r[key].append(getattr(res, key))
        return res

    def recording(self) -> Dict[str, np.ndarray]:
        """Everything shown since the last reset (needs ``record=True``).

        Keys: ``frames`` (T,), ``roots`` (T, 3), ``contacts`` (T, 2), ``lock_weights`` (T, 2),
        and on the full path ``positions``/``local_translations`` (T, J, 3),
        ``rotations``/``local_rotations`` (T, J, 4) and ``animated_feet`` (T, 2, 3, the ankles
        before foot locking and IK), where T = 1 + steps * frames_per_step (the reset pose
        first); per step: ``transitions`` (S,) bool, ``queries`` (S, 12) and ``costs`` (S,)
        (the matched cost).
        """
        if not self._record:
            raise ValueError("this controller was created with record=False")
        per_step = ("transitions", "queries", "costs")
        out = {k: np.concatenate(v) for k, v in self._rec.items() if k not in per_step and v}
        out["transitions"] = np.array(self._rec["transitions"], bool)
        out["queries"] = np.array(self._rec["queries"], np.float32).reshape(-1, TRAJECTORY_DIM)
        out["costs"] = np.array(self._rec["costs"], np.float32)
        out["fps"] = np.float32(self.db.fps)
        out["frames_per_step"] = np.int32(self.frames_per_step)
        return out


def __getattr__(name: str):  # mmrl.character.Controller: the old name, deprecated for one release
    if name == "Controller":
        import warnings

        warnings.warn("Controller is deprecated and will be removed in the next release; use mmrl.Character",
                      DeprecationWarning, stacklevel=2)
        return Character
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
