"""``mmrl play``'s loop without a browser: a policy steering the full-path character live.

:class:`LiveSession` is driven one shown frame at a time (:meth:`LiveSession.step`, 30 per
second). Every ``frames_per_step`` frames (6 = 0.2 s) it makes a decision: the pending user
edits (target, obstacle moves, toggles, policy) take effect, the policy acts on the task's
observation and :class:`mmrl.rollout.FullPath` steps the env and the controller (matching,
inertialization, foot locking, IK). A target set at any time therefore acts at the next
decision: within 0.2 s plus one frame.

Episodes never cut: when the env ends one (target reached, collision, safety cap) the
character goes on where it stands with the user's target (``continue_from_character``),
and an obstacles scene keeps its obstacles where they were.

Live quality numbers are :func:`mmrl.metrics.quality` over the last ``window_steps``
decisions. ``trace``: one JSON line per decision (with ``"facing"`` on a task that reads one), ``{"t", "root": [x, z, yaw], "target":
[x, z], "frame", "transition"}``, written and flushed line by line.
"""
from __future__ import annotations

import json
import threading
import time
from collections import deque
from typing import Any, Dict, Optional

import numpy as np

from .. import _core, metrics
from ..character import Character
from ..motion.database import POSE_DIM
from ..rl.policies import JoystickPolicy
from ..rollout import FullPath, _world_query, policy_actions


#: Timing samples kept per part: 10 minutes of frames at 30 fps.
TIMING_SAMPLES = 18_000


class LiveSession:
    """One character, its task's env and the policies it can switch between."""

    def __init__(self, task, db, policy, *, config=None, stage: Optional[int] = None, seed: int = 0,
                 trace: Optional[str] = None, window_steps: int = 50, request: str = "", compressed=None):
        self.task, self.db = task, db
        self.run = FullPath(task, db, config=config, stage=stage, seed=seed, record=False, continuous=True,
                            request=request, compressed=compressed)
        self.config = self.run.config
        self._scene = task.scene(self.run.env) if task.scene is not None else None  # the task's own scene
        self.takes_facing = self.run.takes_facing
        if self.takes_facing:  # the first episode's facing stays until the user sets another
            self.run.set_facing(self.run.env.env_state(0)["facing"])
        self.policies = {"trained": policy, "joystick": JoystickPolicy.preset(db, "joystick"),
                         "joystick-run": JoystickPolicy.preset(db, "joystick-run")}
        self.policy_name = "trained"
        self.fps = float(db.fps)
        self.F = int(self.config.frames_per_step)
        self.ik, self.inertialization = True, True
        self._lock = threading.Lock()
        self._pending: Dict[str, Any] = {}
        self.obstacles_paused = False
        self._velocities: Optional[np.ndarray] = None  # the obstacles' own velocities while paused
        self.frames_shown = 0
        self.decisions = 0
        self.last: Optional[Any] = None  # the last decision's StepResult
        self.k = self.F  # frames of the last decision shown
        self.shown: Dict[str, Any] = {}
        self.window: deque = deque(maxlen=int(window_steps) + 1)  # + the step whose last frame leads
        # The last TIMING_SAMPLES of each: a list grew by ~150 bytes per frame for as long as
        # `mmrl play` ran (bench/soak.py play: +23 MB/hour).
        self.timing = {k: deque(maxlen=TIMING_SAMPLES)
                       for k in ("policy", "env_and_controller", "controller", "click_to_decision")}
        self._wrap_controller_timing()
        self._trace = open(trace, "a", encoding="utf-8") if trace else None
        pos, _ = self.run.character.pose()
        self.shown = self._frame_values(pos, self.db.contacts[self.run.character.frame])

    # ------------------------------------------------------------------ user edits (any thread)
    def set_target(self, x: float, z: float) -> None:
        """World (x, z) meters; takes effect at the next decision."""
        if not (np.isfinite(x) and np.isfinite(z)):
            raise ValueError(f"target must be finite, got ({x}, {z})")
        with self._lock:
            self._pending["target"] = (float(x), float(z))
            self._pending.setdefault("target_set_at", time.perf_counter())

    def set_policy(self, name: str) -> None:
        if name not in self.policies:
            raise ValueError(f"policy must be one of {sorted(self.policies)}, got {name!r}")
        with self._lock:
            self._pending["policy"] = name

    def set_options(self, *, ik: Optional[bool] = None, inertialization: Optional[bool] = None) -> None:
        """Switch IK (with foot locking) and inertialization; applied at the next decision by a
        new Character on the same frame and root (the C++ options are fixed per character)."""
        with self._lock:
            self._pending["options"] = (self.ik if ik is None else bool(ik),
                                        self.inertialization if inertialization is None else bool(inertialization))

    def set_facing(self, yaw: float) -> None:
        """The facing to arrive with (world yaw, radians), from the next decision on (tasks that
        read one: ``takes_facing``)."""
        if not self.takes_facing or not np.isfinite(yaw):
            raise ValueError(f"facing: the {self.task.name} task reads none" if not self.takes_facing else
                             f"facing must be finite (radians), got {yaw}")
        with self._lock:
            self._pending["facing"] = float(yaw)

    def set_request(self, request: str) -> None:
        """A request over the database's tags ("" for every clip): checked now (ValueError listing
        the tags available), applied at the next decision, like a new target."""
        self.run.playback.check_request(request)
        canon = _core.select_request(self.db._db, request)[0] if request.strip() else ""
        with self._lock:
            self._pending["request"] = canon

    @property
    def request(self) -> str:
        return self.run.request

    def move_obstacle(self, index: int, x: float, z: float) -> None:
        with self._lock:
            self._pending.setdefault("moves", {})[int(index)] = (float(x), float(z))

    def pause_obstacles(self, paused: bool) -> None:
        with self._lock:
            self._pending["pause"] = bool(paused)

    @property
    def has_obstacles(self) -> bool:
        """The task has a scene of obstacles (it declares one: ``Task.scene``)."""
        return self._scene is not None

    @property
    def target(self) -> np.ndarray:
        return self.run.target.copy()

    @property
    def root(self) -> tuple:
        return self.run.character.root

    # ------------------------------------------------------------------ the loop
    def step(self) -> Dict[str, Any]:
        """Show the next frame (deciding first when the last decision's frames are used up).
        Returns what the frame shows (:func:`mmrl.viz.render.recording_frame`'s keys)."""
        if self.k >= self.F:
            self._decide()
        res = self.last
        self.shown = self._frame_values(res.positions[self.k], res.contacts[self.k])
        self.k += 1
        self.frames_shown += 1
        return self.shown

    def _frame_values(self, positions, contacts) -> Dict[str, Any]:
        out = dict(self.shown)
        out.update(positions=positions, contacts=contacts, targets=self.run.target.copy())
        if self.takes_facing:
            out["facing"] = self.run.facing
        if self.has_obstacles:
            out["obstacles"] = self._obstacle_corners()
        return out

    def _apply_pending(self) -> None:
        with self._lock:
            pending, self._pending = self._pending, {}
        if "policy" in pending:
            self.policy_name = pending["policy"]
        if "options" in pending and pending["options"] != (self.ik, self.inertialization):
            self.ik, self.inertialization = pending["options"]
            self._new_controller()
        if self.has_obstacles and ("moves" in pending or "pause" in pending):
            self._edit_obstacles(pending.get("moves", {}), pending.get("pause"))
        if "request" in pending:
            self.run.set_request(pending["request"])
        if "facing" in pending:
            self.run.set_facing(pending["facing"])
        if "target" in pending:
            self.run.set_target(*pending["target"])
            self.timing["click_to_decision"].append(time.perf_counter() - pending["target_set_at"])

    def _decide(self) -> None:
        self._apply_pending()
        run = self.run
        t0 = time.perf_counter()
        action = policy_actions(self.policies[self.policy_name], run.obs[None], layout=run.env.observation_layout).reshape(-1)
        t1 = time.perf_counter()
        low, high = run.env.single_action_space.low, run.env.single_action_space.high
        clipped = np.clip(action, low, high)
        points, directions = _world_query(self.db, clipped, run.character.root)
        root_before = run.character.root
        continuation = self._continuation_path()
        scene_before = self._obstacles_after_step() if self.has_obstacles else None
        out = run.step(action)
        t2 = time.perf_counter()
        self.timing["policy"].append(t1 - t0)
        self.timing["env_and_controller"].append(t2 - t1)
        res = out["res"]
        if out["done"]:
            if scene_before is not None:
                self._restore_obstacles(scene_before)
            run.continue_from_character(run.target)
        self.last, self.k = res, 0
        self.decisions += 1
        self.window.append(res)
        chosen = run.playback.chosen_features(run.env, 0, res.match)
        match_points, match_directions = _world_query(
            self.db, np.asarray(chosen[POSE_DIM:POSE_DIM + 12], np.float32), root_before)
        self.shown.update(query_points=points, query_directions=directions, match_points=match_points,
                          match_directions=match_directions, sensors=self._sensors(),
                          continuation_path=continuation)
        self._write_trace(root_before, res)

    # ------------------------------------------------------------------ controller options
    def _new_controller(self) -> None:
        old = self.run.character
        frame, (x, z, yaw) = old.frame, old.root
        self.run.character = Character(self.db, frames_per_step=self.F,
                                   inertialization_halflife=0.1 if self.inertialization else 0.0, ik=self.ik,
                                   foot_locking=self.ik, action_limit_std=self.config.action_limit_std,
                                   transition_cost=self.config.transition_cost,
                                   position=(x, z), yaw=yaw)
        self.run.playback.restart(self.run.character, self.run.env, 0, frame, (x, z, yaw))  # the pose shown now

    def _wrap_controller_timing(self) -> None:
        """Time the character's playback of each decision: the playback's ``play``, what the full
        path calls whatever the motion source."""
        inner = self.run.playback.play

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            res = inner(*args, **kwargs)
            self.timing["controller"].append(time.perf_counter() - t0)
            return res

        self.run.playback.play = timed

    # ------------------------------------------------------------------ obstacles
    def _obstacle_corners(self) -> np.ndarray:
        from ..tasks.obstacles_scene import obstacle_corners

        return obstacle_corners(self.run.env.obstacles(0)).astype(np.float32)

    def obstacle_centres(self) -> np.ndarray:
        return np.asarray(self.run.env.obstacles(0)["centres"], np.float64)

    def _obstacles_after_step(self) -> Dict[str, np.ndarray]:
        env = self.run.env
        now = env.obstacles(0)
        after = env.obstacles_after(0, self.F)
        return {"centres": after["centres"], "half_sizes": now["half_sizes"], "angles": now["angles"],
                "velocities": after["velocities"]}

    def _restore_obstacles(self, o: Dict[str, np.ndarray]) -> None:
        # The C++ env's scene editing (bound for tests and tools); ObstaclesVectorEnv has no
        # wrapper for it and the task module is not the viewer's to change.
        self.run.env._core.set_obstacles(0, *(np.ascontiguousarray(o[k], np.float32) for k in
                                              ("centres", "half_sizes", "angles", "velocities")))

    def _edit_obstacles(self, moves: Dict[int, tuple], pause: Optional[bool]) -> None:
        o = {k: np.array(v, np.float32) for k, v in self.run.env.obstacles(0).items()}
        half = float(self.config.obstacle_square_half)  # obstacles live (and bounce) in this world square
        for i, (x, z) in moves.items():
            if 0 <= i < len(o["centres"]):
                o["centres"][i] = np.clip((x, z), -half, half)
        if pause is not None and pause != self.obstacles_paused:
            self.obstacles_paused = pause
            if pause:
                self._velocities = o["velocities"].copy()
                o["velocities"][:] = 0.0
            elif self._velocities is not None and len(self._velocities) == len(o["velocities"]):
                o["velocities"] = self._velocities
        self._restore_obstacles(o)

    def _continuation_path(self) -> Optional[Dict[str, np.ndarray]]:
        """At a decision: the path the clip being played would take if it continued (its frame's
        ``Database.path_samples``, world (x, z), (9, 2)) and which samples the collision-aware
        search's test finds inside an obstacle (from the first hit on); None without obstacles or
        when the clip cannot continue."""
        if self._scene is None:
            return None
        env = self.run.env
        state = env.env_state(0)
        path = self.run.playback.continuation(env, 0)  # the path the motion shown now would take
        if path is None:
            return None
        local, hit = path
        c, s = np.cos(state["yaw"]), np.sin(state["yaw"])
        world = local @ np.array([[c, s], [-s, c]]).T + np.array([state["x"], state["z"]])
        inside = (np.asarray(_core.PATH_SAMPLE_FRAMES) >= hit) if hit > 0 else np.zeros(len(world), bool)
        return {"points": world.astype(np.float32), "inside": inside}

    def _sensors(self) -> Optional[Dict[str, np.ndarray]]:
        return None if self._scene is None else self._scene.sensors()

    # ------------------------------------------------------------------ quality, trace, timing
    def quality(self) -> Dict[str, Any]:
        """:func:`mmrl.metrics.quality` of the last ``window_steps`` decisions' frames (the frame
        shown before them leads, as a recording's reset pose does); {} before two decisions."""
        steps = list(self.window)
        if len(steps) < 2:
            return {}
        lead, steps = steps[0], steps[1:]

        def frames(key):
            return np.concatenate([getattr(lead, key)[-1:]] + [getattr(s, key) for s in steps])

        rec = {key: frames(key) for key in ("positions", "roots", "frames", "contacts", "animated_feet")}
        rec["transitions"] = np.array([s.transition for s in steps])
        rec["costs"] = np.array([s.cost for s in steps], np.float32)
        out = metrics.quality(self.db, rec)
        out["seconds"] = len(steps) * self.F / self.fps
        return out

    def _write_trace(self, root, res) -> None:
        if self._trace is None:
            return
        t = self.frames_shown / self.fps
        line = {"t": round(t, 4), "root": [round(float(v), 5) for v in root],
                "target": [round(float(v), 5) for v in self.run.target], "frame": int(res.match),
                "transition": bool(res.transition)}
        if self.takes_facing:
            line["facing"] = round(float(self.run.env.env_state(0)["facing"]), 5)
        self._trace.write(json.dumps(line) + "\n")  # one write per line: a reader never sees half a line
        self._trace.flush()

    def timing_ms(self) -> Dict[str, float]:
        """Mean milliseconds per decision of each part (over the last TIMING_SAMPLES decisions)."""
        return {k: 1000.0 * float(np.mean(v)) for k, v in self.timing.items() if v and k != "click_to_decision"}

    def close(self) -> None:
        if self._trace is not None:
            self._trace.close()
            self._trace = None
