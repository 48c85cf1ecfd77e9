"""The two episode loops, for every task and every policy.

- **Fast path** (:func:`first_episodes`, :func:`evaluate_fast`): a batched vector env, one
  episode per environment; success, outcomes and time to target. What training sees.
- **Full path** (:class:`FullPath`, :func:`evaluate_full_path`, :func:`follow`): a 1-env
  vector env (the task: starts, targets, obstacles, success, termination) and a full-path
  :class:`~mmrl.character.Character` (poses, inertialization, foot locking, IK) stepped
  side by side with the same start, root and actions. Both take the same decisions
  (``decision.hpp``), so their roots agree and the env's scene is exactly the one the
  character moves through.

A *policy* is anything with ``act(obs[N, D], deterministic=True) -> actions[N, A]``:
trained policies (:func:`mmrl.load_policy`) and the scripted joysticks
(:mod:`mmrl.policies`).

Each metric is defined once: time to target is ``episode_frames / fps``, the frames played
in the episode up to the one that reached the target (``infos["episode_frames"]``); the
motion-quality metrics are :func:`mmrl.metrics.quality`.
"""
from __future__ import annotations

# size: the fast and the full episode loops with the recorders only they use (FullPath, its
# episode summary, follow's log), so the full path's recording keys live in one module.

import inspect
from typing import Any, Dict, List, Optional

import numpy as np

from . import _core, metrics
from .character import Character
from .motion.database import POSE_DIM, Database
from .motion.playback import playback_of
from .tasks import Task
from .tasks.layout import obs_segment

#: Per-shown-frame keys of a controller recording (trimmed together).
FRAME_KEYS = ("frames", "roots", "positions", "rotations", "local_translations", "local_rotations", "contacts",
              "lock_weights", "animated_feet")
#: Per-step keys of a controller recording.
STEP_KEYS = ("transitions", "queries", "costs")


def policy_actions(policy, obs: np.ndarray, deterministic: bool = True, layout=None) -> np.ndarray:
    """``policy.act(obs, deterministic=...)`` (or ``policy.act(obs)`` for policies without the
    flag). The signature decides, not a caught TypeError, so a bug inside ``act`` is never retried.
    ``layout``: the env's ``observation_layout``, handed to a policy that reads segments by name
    (a scripted joystick's ``bind_layout``) before it acts."""
    if layout is not None and hasattr(policy, "bind_layout"):
        policy.bind_layout(layout)
    try:
        takes_flag = "deterministic" in inspect.signature(policy.act).parameters
    except (TypeError, ValueError):  # builtins without a signature
        takes_flag = False
    actions = policy.act(obs, deterministic=deterministic) if takes_flag else policy.act(obs)
    return np.asarray(actions, np.float32)


def _check_episodes(episodes: int) -> int:
    if int(episodes) < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    return int(episodes)


# ----------------------------------------------------------------------------- fast path
def first_episodes(env, policy, seed: int, deterministic: bool = True) -> Dict[str, np.ndarray]:
    """Run vector env ``env`` until each environment's first episode has ended.

    Returns arrays (one entry per environment) of ``success``, ``length`` (steps),
    ``frames`` (frames played) and every other boolean per-episode info the env reports
    (``collision``...). Closes ``env``.
    """
    n = env.num_envs
    obs, _ = env.reset(seed=seed)
    done = np.zeros(n, bool)
    out: Dict[str, np.ndarray] = {"success": np.zeros(n, bool), "truncated": np.zeros(n, bool),
                                  "length": np.zeros(n, np.int64), "frames": np.zeros(n, np.int64)}
    while not done.all():
        obs, _, term, trunc, info = env.step(policy_actions(policy, obs, deterministic, env.observation_layout))
        ended = (term | trunc) & ~done
        if not ended.any():
            continue
        out["length"][ended] = info["episode_length"][ended]
        out["frames"][ended] = info["episode_frames"][ended]
        out["truncated"][ended] = (trunc & ~term)[ended]
        for key, value in info.items():  # success and the task's boolean outcomes (collision, ...)
            if not key.startswith("_") and np.asarray(value).dtype == bool:
                out.setdefault(key, np.zeros(n, bool))[ended] = value[ended]
        done |= ended
    env.close()
    return out


def summarize_outcomes(task: Task, success: np.ndarray, outcomes: Dict[str, np.ndarray]) -> Dict[str, float]:
    """success_rate with its binomial standard error, and ``<outcome>_rate`` of the task's outcomes."""
    p = float(np.mean(success))
    out = {"success_rate": p, "success_stderr": float(np.sqrt(p * (1 - p) / len(success)))}
    for key in task.outcomes:
        rate_key = "truncation_rate" if key == "truncated" else f"{key}_rate"
        out[rate_key] = float(np.mean(outcomes[key])) if key in outcomes else 0.0
    return out


def evaluate_fast(task: Task, db: Database, policy, *, episodes: int = 1000, seed: int = 12345, config=None,
                  stage: Optional[int] = None, deterministic: bool = True, num_threads: int = 0) -> Dict[str, Any]:
    """``episodes`` episodes of ``task`` on the fast path (one per environment of one batched env).

    The same seed gives the same episodes (starts, targets, scenes) for every policy, so
    policies can be compared. ``stage``: the task's curriculum stage (default: its last).
    Returns ``episodes``, ``success_rate``, ``success_stderr``, ``mean_time_to_target_s``
    (successful episodes, frame-exact), ``mean_steps``, the task's outcome rates, and
    ``stage`` for tasks with stages.
    """
    episodes = _check_episodes(episodes)
    env = task.make_vector_env(episodes, db=db, config=config, num_threads=num_threads)
    stage = apply_stage(task, env, stage)
    r = first_episodes(env, policy, seed, deterministic)
    success = r["success"]
    out: Dict[str, Any] = {"episodes": episodes}
    if stage is not None:
        out["stage"] = int(stage)
    out.update(summarize_outcomes(task, success, r))
    out["mean_time_to_target_s"] = float(r["frames"][success].mean() / db.fps) if success.any() else float("nan")
    out["mean_steps"] = float(r["length"].mean())
    return out


def apply_stage(task: Task, env, stage: Optional[int]) -> Optional[int]:
    """Put ``env`` at curriculum ``stage`` (default: the task's last); None for tasks without stages."""
    if not task.stages:
        if stage is not None:
            raise ValueError(f"stage: the {task.name} task has no curriculum stages")
        return None
    stage = task.stages if stage is None else int(stage)
    if not 1 <= stage <= task.stages:
        raise ValueError(f"stage must be in 1..{task.stages}, got {stage}")
    task.set_stage(env, stage)
    return stage


# ----------------------------------------------------------------------------- full path
def _world_query(db: Database, action: np.ndarray, root) -> tuple:
    """The three future positions and directions (3, 2) of a 12-d normalized action, world (x, z)."""
    raw = db.denormalize(np.concatenate([np.zeros(POSE_DIM, np.float32), action]))[POSE_DIM:].reshape(3, 4)
    x, z, yaw = root
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, s], [-s, c]])  # character (x, z) -> world (x, z)
    return raw[:, :2] @ rot.T + np.array([x, z]), raw[:, 2:] @ rot.T


class FullPath:
    """A task's 1-env vector env and the full-path controller stepped together.

    Args:
        task: the task; db: the database; config: the task's numbers; stage: curriculum
            stage (tasks with stages; default the last); seed: the env's seed;
        scene: also record the task's scene (obstacles, sensor maps, hit points) per step;
        continuous: at an episode's end keep the character where it is (the caller then
            calls :meth:`continue_from_character`) instead of moving it to the env's new start;
        request: a request over the database's tags (``"style=elderly"``, docs/styles.md),
            pinned on the env before its first episode, so episodes start and play inside it;
        compressed: a :class:`~mmrl.compress.model.CompressedModel` of ``db``: the env
            decides by its projector and plays by its stepper and decompressor (episode starts
            stay the database frames the env draws, from their states); the character shows the
            decoded poses. The same policy, decision interval and transition cost
            (docs/compressed.md). Not with ``request``: a projection keeps to no tags;
        the rest: :class:`~mmrl.character.Character` options.
    """

    def __init__(self, task: Task, db: Database, *, config=None, stage: Optional[int] = None, seed: int = 0,
                 ik: bool = True, foot_locking: bool = True, inertialization_halflife: float = 0.1,
                 fast: bool = False, record: bool = True, scene: bool = False, continuous: bool = False,
                 request: str = "", compressed=None):
        self.task, self.db = task, db
        self.continuous = bool(continuous)
        self.env = task.make_vector_env(1, db=db, config=config, num_threads=1)
        self.compressed = compressed
        self.playback = playback_of(db, compressed)  # how the character shows the env's decisions
        if request:
            self.playback.check_request(request)
        self.playback.attach(self.env)
        self.facing: Optional[float] = None  # a facing set by set_facing (None: each episode's own)
        self.request = ""
        self.request_clips: Optional[np.ndarray] = None  # (C,) bool of the request's clips; None: every clip
        if request:
            self.set_request(request)
        self.config = self.env.config
        self.stage = apply_stage(task, self.env, stage)
        self.character = Character(db, frames_per_step=self.config.frames_per_step,
                               inertialization_halflife=inertialization_halflife, ik=ik, foot_locking=foot_locking,
                               fast=fast, action_limit_std=self.config.action_limit_std, record=record,
                               transition_cost=self.config.transition_cost)
        self.scene = task.scene(self.env) if scene and task.scene is not None else None
        obs, _ = self.env.reset(seed=int(seed))
        self.obs = obs[0]
        self.last_recording: Optional[Dict[str, np.ndarray]] = None
        self._start_episode()

    @property
    def ctrl(self):
        """Deprecated: :attr:`character` (goes in the next release)."""
        import warnings

        warnings.warn("FullPath.ctrl is deprecated; use FullPath.character", DeprecationWarning, stacklevel=2)
        return self.character

    def _start_episode(self) -> None:
        s = self.env.env_state(0)
        self.playback.start(self.character, self.env, 0, (s["x"], s["z"], s["yaw"]))
        self.target = np.array(s["target"], np.float64)
        self.episode_steps = 0

    def set_request(self, request: str) -> None:
        """Pin a request (``""`` for every clip) from the next decision on (ValueError listing the
        tags available when it names an unknown one or selects nothing, or when the motion source
        keeps to none)."""
        self.playback.check_request(request)
        self.obs = self.env.set_request(0, request)
        self.request = self.env.request(0)
        self.request_clips = (None if not self.request else
                              np.asarray(_core.select_request(self.db._db, self.request)[1], bool))

    def set_target(self, x: float, z: float) -> None:
        """Move the current episode's target (world meters)."""
        self.obs = self.env.set_target(0, x, z)
        self.target = np.array([x, z], np.float64)

    @property
    def takes_facing(self) -> bool:
        """The task reads a target facing (its observation has a "facing" segment: the arrive task)."""
        return any(name == "facing" for name, _ in self.env.observation_layout)

    def set_facing(self, yaw: float) -> None:
        """The target facing (world yaw, radians) from the next decision on, kept by
        :meth:`continue_from_character`; ValueError for a task that reads none."""
        if not self.takes_facing:
            raise ValueError(f"the {self.task.name} task reads no facing")
        self.obs = self.env.set_facing(0, yaw)
        self.facing = float(yaw)

    def continue_from_character(self, target=None) -> None:
        """Start the next episode where the character stands (same frame and root) with a new
        world ``target``, instead of the env's fresh start: one continuous motion. Without a
        target, one is drawn by the task's episode-start rule (uniform in the square of
        ``target_half_extent``, not too close) around the character, from the env's own random
        stream (the C++ rule, not a copy of it)."""
        x, z, yaw = self.character.root
        self.playback.keep_played(self.env, 0)  # the env's autoreset drew a new start since
        self.env.set_state(0, self.character.frame, x, z, yaw)  # frame -1 (no database frame): the env keeps its state
        if target is None:
            target = self.env._core.draw_target_around_root(0, float(self.config.target_half_extent))
        self.set_target(float(target[0]), float(target[1]))
        if self.facing is not None:
            self.set_facing(self.facing)
        self.episode_steps = 0

    def step(self, action: np.ndarray) -> Dict[str, Any]:
        """One RL step of both. Returns the env's outcome, the controller's StepResult
        (``res``), ``step_frames`` (frames of the step played before the episode ended; ``shown``
        is its old name, kept for one release), the task scene's per-step values, and at an
        episode's end its infos."""
        a = np.asarray(action, np.float32).reshape(1, -1)
        out: Dict[str, Any] = {"target": self.target.copy()}
        if self.scene is not None:
            out.update(self.scene.before_step(a[0]))
        obs, reward, term, trunc, info = self.env.step(a)
        # The controller plays the env's decision; it never decides again, so it cannot drift.
        match, cost = self.env.last_step_decision(0)
        res = self.playback.play(self.character, self.env, 0, match, cost, a[0])
        self.episode_steps += 1
        done = bool(term[0] or trunc[0])
        self.obs = obs[0]
        shown = int(self.env.step_frames[0])
        out.update(res=res, reward=float(reward[0]), terminated=bool(term[0]), truncated=bool(trunc[0] and not term[0]),
                   done=done, step_frames=shown, shown=shown, success=False)
        if self.scene is not None:
            out.update(self.scene.after_step(shown))
        if done:
            for key, value in info.items():
                if not key.startswith("_") and key != "final_obs":
                    out[key] = value[0].item()
            # The env's last goal vector, read at the ending frame, against the controller's root there.
            g = obs_segment(self.env.observation_layout, "goal")
            out["goal_error"] = self._goal_error(info["final_obs"][0, g], res.roots[shown - 1])
            if self.task.final_values is not None:
                out.update(self.task.final_values(self.env.observation_layout, info["final_obs"][0]))
            if not self.continuous:
                if self.character._record:
                    self.last_recording = self.recording(trim=res.frames.size - shown)
                self._start_episode()
        return out

    def _goal_error(self, goal: np.ndarray, root: np.ndarray) -> float:
        dx, dz = self.target[0] - root[0], self.target[1] - root[1]
        c, s = np.cos(root[2]), np.sin(root[2])
        return float(np.hypot(c * dx - s * dz - goal[0], s * dx + c * dz - goal[1]))

    def recording(self, trim: int = 0) -> Dict[str, np.ndarray]:
        """The controller's recording of the current episode without its last ``trim`` shown frames."""
        rec = self.character.recording()
        if trim:
            for k in FRAME_KEYS + ("natural_motion",):  # natural_motion: one row per frame after the first
                if k in rec:
                    rec[k] = rec[k][:-trim]
        return rec

    def root_error(self) -> tuple:
        """(|frame difference|, max |root difference|) between the env and the controller now."""
        s = self.env.env_state(0)
        d = np.abs(np.array([s["x"], s["z"]]) - np.array(self.character.root[:2]))
        dyaw = abs((s["yaw"] - self.character.root[2] + np.pi) % (2 * np.pi) - np.pi)
        return abs(int(s["frame"]) - self.character.frame), float(max(d.max(), dyaw))


class EpisodeSummary:
    """Collects full-path episodes and their quality metrics into the summary ``mmrl eval`` prints.

    The quality keys are :mod:`mmrl.metrics`' (pooled over every episode's frames), plus
    ``raw_mocap`` (:func:`mmrl.metrics.raw_mocap_floor`) so each number reads against the data's
    own; with ``fast`` (root motion only) the pose metrics are None.
    """

    def __init__(self, task: Task, db: Database, fast: bool, stage: Optional[int]):
        self.task, self.db, self.fast, self.stage = task, db, fast, stage
        self.results: List[Dict[str, Any]] = []
        self.quality = metrics.QualityAccumulator()
        self.transitions = self.frames = 0
        self.distance = 0.0  # meters the root travelled over the shown frames
        self.request_clips: Optional[np.ndarray] = None  # set by a caller that evaluates under a request
        self.inside = self.shown = 0  # shown frames inside the request's clips, and all shown frames
        self.costs: List[np.ndarray] = []

    def add(self, ep: Dict[str, Any], rec: Dict[str, np.ndarray], frames: int) -> None:
        """Adds one episode of ``frames`` shown frames (``ep`` gets its quality metrics unless ``fast``)."""
        if not self.fast:
            ep.update(self.quality.add(self.db, rec))
        self.transitions += int(rec["transitions"].sum())
        if self.request_clips is not None:
            shown = np.asarray(rec["frames"])[: int(frames) + 1]
            self.inside += int(self.request_clips[self.db.frame_clip[shown]].sum())
            self.shown += int(shown.size)
        roots = np.asarray(rec["roots"], np.float64)[: int(frames) + 1]
        self.distance += float(np.hypot(*np.diff(roots[:, :2], axis=0).T).sum()) if len(roots) > 1 else 0.0
        self.frames += int(frames)
        self.costs.append(rec["costs"])
        self.results.append(ep)

    def _final_keys(self) -> List[str]:
        """The keys of the task's final values (Task.final_values: named ``final_...``)."""
        if self.task.final_values is None:
            return []
        return sorted({k for e in self.results for k in e if k.startswith("final_")})

    def summary(self) -> Dict[str, Any]:
        results = self.results
        times = [e["time_to_target_s"] for e in results if e["success"]]
        out: Dict[str, Any] = {"episodes": len(results)}
        out.update(summarize_outcomes(self.task, np.array([e["success"] for e in results]),
                                      {k: np.array([e.get(k, False) for e in results]) for k in self.task.outcomes}))
        out.pop("success_stderr")
        out["mean_time_to_target_s"] = float(np.mean(times)) if times else None
        for key in self._final_keys():  # the task's final values over the successful episodes
            values = [e[key] for e in results if e["success"] and key in e]
            out[f"{key}_median"] = float(np.median(values)) if values else None
            out[f"{key}_p95"] = float(np.percentile(values, 95)) if values else None
        out.update(self.quality.result())
        out["transitions_per_s"] = metrics.rate_per_second(self.transitions, self.frames, self.db.fps)
        out["mean_speed_m_per_s"] = metrics.rate_per_second(self.distance, self.frames, self.db.fps)
        if self.request_clips is not None:
            out["request_fidelity"] = self.inside / self.shown if self.shown else None
        costs = np.concatenate(self.costs) if self.costs else np.zeros(0)
        out["matched_cost_mean"] = float(costs.mean()) if costs.size else None
        out["mean_steps"] = float(np.mean([e["steps"] for e in results]))
        if not self.fast:
            floor = metrics.raw_mocap_floor(self.db)
            out["raw_mocap"] = {k: floor[k] for k in ("foot_sliding_cm_per_s", "foot_sliding_p95_cm_per_s",
                                                      "pose_jump_p99_cm")}
        if self.stage is not None:
            out["stage"] = self.stage
        out["episode_results"] = results
        return out


def evaluate_full_path(task: Task, db: Database, policy, *, episodes: int = 20, seed: int = 0, config=None,
                       stage: Optional[int] = None, ik: bool = True, foot_locking: bool = True,
                       inertialization_halflife: float = 0.1, fast: bool = False,
                       target_distance: Optional[float] = None, request: str = "",
                       compressed=None) -> Dict[str, Any]:
    """Run ``episodes`` full-path episodes of ``task`` (back to back in one env, so the same
    seed gives the same episodes for every policy).

    ``target_distance`` (meters) puts every target at that distance from the start in a
    uniformly random direction instead of the task's own draw. ``request`` (docs/styles.md)
    keeps every episode inside the clips carrying it; the result then has ``request`` and
    ``request_fidelity``, the fraction of shown frames from those clips.

    Returns success_rate, mean_time_to_target_s (successful episodes), the task's outcome
    rates, the quality metrics of :mod:`mmrl.metrics` over all shown frames of all episodes
    (pooled samples), ``raw_mocap`` (the database's clips played straight, the same metrics),
    mean_steps and per-episode details (each with its own quality metrics).
    """
    episodes = _check_episodes(episodes)
    run = FullPath(task, db, config=config, stage=stage, seed=seed, ik=ik, foot_locking=foot_locking,
                   inertialization_halflife=inertialization_halflife, fast=fast, record=True, request=request,
                   compressed=compressed)
    rng = np.random.default_rng(seed)
    summary = EpisodeSummary(task, db, fast, run.stage)
    summary.request_clips = run.request_clips
    for _ in range(episodes):
        start = np.array(run.character.root[:2], np.float64)
        if target_distance is not None:
            angle = rng.uniform(-np.pi, np.pi)
            run.set_target(*(start + float(target_distance) * np.array([np.sin(angle), np.cos(angle)])))
        distance = float(np.hypot(*(run.target - start)))
        while True:
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            if out["done"]:
                break
        frames = int(out["episode_frames"])
        ep = {"success": out["success"], "time_to_target_s": frames / db.fps if out["success"] else None,
              "steps": int(out["episode_length"]), "distance_m": distance, "truncated": out["truncated"]}
        for key in task.outcomes:
            ep.setdefault(key, bool(out.get(key, False)))
        ep.update({k: v for k, v in out.items() if k.startswith("final_")})  # the task's final values
        summary.add(ep, run.last_recording, frames)
    out = summary.summary()
    if run.request:
        out["request"] = run.request
    return out


def follow(task: Task, db: Database, policy, *, seconds: float = 10.0, seed: int = 0, config=None,
           stage: Optional[int] = None, continuous: Optional[bool] = None, ik: bool = True,
           foot_locking: bool = True, inertialization_halflife: float = 0.1, request: str = "",
           compressed=None) -> Dict[str, np.ndarray]:
    """Drive the character for ``seconds`` of shown frames, for video and export.

    ``continuous`` (default: tasks without a scene): when an episode ends the character
    goes on where it stands, with a new target drawn around it like the task's, so the
    motion never cuts (one episode index throughout). Otherwise episodes follow each other
    with a cut at each new start.

    Returns per shown frame (T): the controller's recording keys (``positions``, ``roots``,
    ``frames``, ...), ``targets`` (T, 2), ``episode`` (T,) and the scene's per-frame keys
    (``obstacles``); per step (S): ``query_frames`` (shown-frame index of each decision),
    ``query_points`` / ``query_directions`` (S, 3, 2) world (x, z) of the clipped action, and
    the scene's per-step keys; ``outcomes`` (E,) 0 running, 1 success, 2 other ending (a
    task outcome such as a collision), 3 truncated; ``stage``; and the quality metrics.
    ``compressed`` plays a compressed controller (:class:`FullPath`; ``frames`` are then -1).
    """
    if not seconds > 0:
        raise ValueError(f"seconds must be positive, got {seconds!r}")
    continuous = task.scene is None if continuous is None else bool(continuous)
    run = FullPath(task, db, config=config, stage=stage, seed=seed, ik=ik, foot_locking=foot_locking,
                   inertialization_halflife=inertialization_halflife, record=True, scene=True,
                   continuous=continuous, request=request, compressed=compressed)
    low, high = run.env.single_action_space.low, run.env.single_action_space.high
    total = max(2, int(round(seconds * db.fps)))
    log = FollowLog(run)
    while log.frames_so_far() < total:
        action = policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1)
        points, directions = _world_query(db, np.clip(action, low, high), run.character.root)
        out = run.step(action)
        log.add_step(out, points, directions)
        if out["done"]:
            log.end_episode(out)
            if continuous:
                run.continue_from_character()
            elif log.frames_so_far() < total:
                log.start_episode()
    return log.result()


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
        step_values = self.run.playback.step_values(self.run.env, 0, out["res"].match)  # the source's, then the scene's
        for key, value in [*step_values.items(), *out.get("scene_step", {}).items()]:
            self.per_step.setdefault(key, []).append(value)
        # A continuous run shows the whole step; a cut one only up to the ending frame.
        shown = out["res"].frames.size if self.run.continuous else out["step_frames"]
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
