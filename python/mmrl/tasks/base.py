"""What every target-reaching task shares: its config, the vector env over a batched C++
core, the single-env adapter, and the :class:`Task` record that plugs a task into the
commands, evaluation, rendering and export.

A task module (``mmrl.tasks.plane``, ``mmrl.tasks.obstacles``, or your own, see
docs/architecture.md) declares a config dataclass (a :class:`TaskConfig`), a
:class:`TargetVectorEnv` subclass naming its C++ core, and one :class:`Task`; registering
that Task (``mmrl.tasks.register_task``) is the one line that makes ``mmrl train NAME``,
``mmrl eval``, ``render`` and ``export-bvh`` work with it.

The vector env contract (gymnasium 1.x): ``reset(seed=s)`` gives env i a random stream
derived from (s, i); ``step`` returns ``(obs, rewards, terminated, truncated, infos)`` and,
where episodes ended, ``infos`` holds ``final_obs``, ``success``, ``episode_return``,
``episode_length`` and ``episode_frames`` (frames played in the episode, the last step
counted up to the frame that ended it), each with its ``_key`` mask, plus the task's own
keys (``Task.episode_infos``). ``observation_layout`` names the observation's segments.

Autoreset: SAME_STEP by default (the ending step returns the next episode's first
observation; the last one is ``infos["final_obs"]``). ``autoreset_mode=AutoresetMode.NEXT_STEP``
(what RLlib expects) returns the last observation itself, and the env's next step ignores its
action and returns the first observation of the next episode, with reward 0 and both flags
False. Each env draws its episodes from its own stream: both modes play the same episodes.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, ClassVar, Dict, Mapping, Optional, Sequence, Tuple, Type, Union

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..motion.clip_costs import clip_cost_array
from ..motion.database import Database
from ..motion.sources import resolve_database
from ..motion.tags import request_group_list
from .options import check_retired
from .requests import RequestMethods


# ----------------------------------------------------------------------------- config
class TaskConfig:
    """What every task's config shares: copies with overrides, and the C++ config struct, by
    field name. A task's config is a dataclass made from its C++ option table
    (``@task_options(_core.MyTaskConfig)``, :mod:`mmrl.tasks.options`): the shared numbers
    (frames per step, target square, success radius and bonus, step limit, action box,
    transition cost and reward terms, clip costs, request groups) and the task's own, each with
    its default, range and doc (``option_info``)."""

    #: The task's name in error messages ("plane-task option ...").
    task_label = "task"
    #: The C++ config class and its option table (set by ``task_options``).
    core_type: ClassVar[Any] = None
    option_table: ClassVar[Mapping[str, Any]] = {}

    #: Fields the trainer reads and the C++ core never sees (``Task.training_config``).
    training_only: ClassVar[Tuple[str, ...]] = ()
    #: Options that shape what a trained policy observes or how its action is read: a deployment
    #: (``--set`` on eval, export, play) cannot change them.
    policy_inputs: ClassVar[Tuple[str, ...]] = ("frames_per_step", "action_limit_std", "request_groups")
    #: Options of experiments that lost, removed from the code (``options.check_retired``).
    retired: ClassVar[Mapping[str, Any]] = {}

    def replace(self, **overrides) -> "TaskConfig":
        """A copy with ``overrides`` applied; an unknown name: TypeError (a retired one: ValueError)."""
        check_retired(type(self), overrides, every_value=True)
        names = [f.name for f in fields(self)]
        unknown = [k for k in overrides if k not in names]
        if unknown:
            raise TypeError(f"unknown {self.task_label} option {unknown[0]!r}; options are {names}")
        values = asdict(self)
        values.update(overrides)
        return type(self)(**values)

    def to_core(self, core_config_type=None, db: Optional[Database] = None):
        """The matching C++ config struct (every field copied by name; ``clip_costs`` resolved
        against ``db``'s clips, which it then needs); ``core_config_type``: ``core_type``."""
        c = (core_config_type or self.core_type)()
        for f in fields(self):
            if f.name in self.training_only:
                continue
            value = getattr(self, f.name)
            if f.name == "clip_costs":
                value = clip_cost_array(value, db).tolist() if value else []
            elif f.name == "request_groups":
                value = request_group_list(value)
            try:
                setattr(c, f.name, value)
            except TypeError:  # pybind11's list of signatures says nothing a user can act on
                kind = self.option_table[f.name].kind if f.name in self.option_table else type(value).__name__
                raise ValueError(f"{self.task_label} option {f.name}: expected {_KIND_WORDS.get(kind, kind)}, "
                                 f"got {value!r}") from None
        return c


_KIND_WORDS = {"float": "a number", "int": "a whole number", "bool": "true or false"}


def make_config(config_type, config=None, overrides: Optional[Mapping[str, Any]] = None):
    """``config`` (or the defaults) with ``overrides`` applied, as a new ``config_type``."""
    base = config_type(**asdict(config)) if config is not None else config_type()
    return base.replace(**dict(overrides or {}))


def check_actions(actions, shape, finite: bool = True) -> np.ndarray:
    """``actions`` as a C-contiguous float32 array of ``shape``; refuses other shapes, ints and
    (unless ``finite`` is False: the C++ step checks them itself) NaN."""
    try:
        a = np.asarray(actions)
    except ValueError as e:  # ragged nested lists
        raise ValueError(f"actions: expected an array of shape {tuple(shape)} ({e})") from None
    if a.shape != tuple(shape):
        raise ValueError(f"actions: expected shape {tuple(shape)}, got {a.shape}")
    if a.dtype != np.float32:
        if not np.issubdtype(a.dtype, np.floating):
            raise TypeError(f"actions: expected a float array, got dtype {a.dtype}")
        a = np.ascontiguousarray(a, dtype=np.float32)
    elif not a.flags.c_contiguous:
        a = np.ascontiguousarray(a)
    if finite and not np.isfinite(a).all():
        raise ValueError("actions: contains NaN or inf")
    return a


def parse_autoreset_mode(mode) -> AutoresetMode:
    """``AutoresetMode.SAME_STEP``/``NEXT_STEP``, from the enum, its value (``"NextStep"``) or a
    snake-case name (``"next_step"``); other modes raise ValueError."""
    supported = (AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP)
    if not isinstance(mode, AutoresetMode):
        key = str(mode).replace("_", "").lower()
        mode = next((m for m in AutoresetMode if m.value.lower() == key), mode)
    if mode not in supported:
        raise ValueError(f"autoreset_mode must be one of {[m.value for m in supported]} (or same_step / next_step), "
                         f"got {mode!r}")
    return mode


# ----------------------------------------------------------------------------- vector env
class TargetVectorEnv(RequestMethods, VectorEnv):
    """N characters of one task stepped together by a batched C++ core.

    Subclasses set ``core_type`` (the ``_core`` class), ``config_type`` (a TaskConfig
    dataclass) and ``core_config_type``, and may override :meth:`_observation_space`,
    :meth:`_step_core` (extra per-env output buffers) and :meth:`_task_infos` (extra
    per-episode infos). The Python side only holds spaces, buffers, autoreset bookkeeping
    and infos; all work happens in C++ with the GIL released.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": [], "render_fps": 30}
    core_type: Any = None
    core_config_type: Any = None
    config_type: Any = None

    def __init__(self, num_envs: int = 64, *, db: Union[Database, str, os.PathLike, None] = None,
                 data=None, config=None, num_threads: int = 0, render_mode: Optional[str] = None,
                 autoreset_mode: Union[AutoresetMode, str] = AutoresetMode.SAME_STEP, **overrides):
        autoreset_mode = parse_autoreset_mode(autoreset_mode)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        self.db = resolve_database(db, data)
        self.config = make_config(self.config_type, config, overrides)
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self._core = self.core_type(self.db._db, self.db.matcher, self.num_envs,
                                    self.config.to_core(self.core_config_type, self.db), num_threads)
        self.autoreset_mode = autoreset_mode
        self.metadata = {**type(self).metadata, "autoreset_mode": autoreset_mode}
        self._core.autoreset_next_step = autoreset_mode == AutoresetMode.NEXT_STEP
        self.obs_dim, self.act_dim = int(self._core.obs_dim), int(self.core_type.action_dim)
        self.observation_layout = tuple((str(n), int(k)) for n, k in self._core.obs_layout)  # tasks/layout.py
        self.single_observation_space = self._observation_space()
        self.single_action_space = gym.spaces.Box(self._core.action_low, self._core.action_high, (self.act_dim,),
                                                  np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n = self.num_envs
        self._obs = np.zeros((n, self.obs_dim), np.float32)
        self._final_obs = np.zeros((n, self.obs_dim), np.float32)
        self._rewards = np.zeros(n, np.float32)
        self._terminated = np.zeros(n, np.uint8)
        self._truncated = np.zeros(n, np.uint8)
        self._success = np.zeros(n, np.uint8)
        self._ep_return = np.zeros(n, np.float32)
        self._ep_length = np.zeros(n, np.int32)
        self._step_frames = np.zeros(n, np.int32)
        self._ep_frames = np.zeros(n, np.int64)  # written by the C++ step where an episode ended
        # The last step's decisions (their running sums since pop_match_stats, training's cheap
        # quality log, are kept in C++).
        self._step_transitions = np.zeros(n, np.uint8)
        self._step_costs = np.zeros(n, np.float32)
        # NEXT_STEP: envs whose next step is their reset (no decision is made in it).
        self._pending = np.zeros(n, bool)
        self._any_pending = False
        self._seeded = False

    # -- hooks -------------------------------------------------------------------------------
    def _observation_space(self) -> gym.spaces.Box:
        return gym.spaces.Box(-np.inf, np.inf, (self.obs_dim,), np.float32)

    def _task_step_buffers(self) -> tuple:
        """The task's own step outputs, in the order its core's step takes them after ``success``
        (the obstacles task: collision, hits)."""
        return ()

    def _step_core(self, actions: np.ndarray, obs: np.ndarray) -> None:
        """One C++ step writing every output buffer (the observations into ``obs``), this step's
        frames and decisions included: the one call a step makes."""
        self._core.step(actions, obs, self._rewards, self._terminated, self._truncated, self._success,
                        *self._task_step_buffers(), self._final_obs, self._ep_return, self._ep_length,
                        step_frames=self._step_frames, transitions=self._step_transitions, costs=self._step_costs,
                        episode_frames=self._ep_frames)

    def _task_infos(self, done: np.ndarray) -> Dict[str, np.ndarray]:
        """Extra per-episode infos where ``done`` (each gets a ``_key`` mask)."""
        return {}

    def _on_reset(self, which: Optional[np.ndarray]) -> None:
        """Called after envs were reset (``which`` None = all)."""

    # -- gymnasium ---------------------------------------------------------------------------
    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is None and not self._seeded:
            seed = int(np.random.SeedSequence().generate_state(1, np.uint64)[0])
        if seed is not None:
            if isinstance(seed, (list, tuple)):
                raise TypeError("seed: give one int; environment i derives its stream from (seed, i)")
            self._core.reset(int(seed) & 0xFFFFFFFFFFFFFFFF, self._obs)
            self._seeded = True
        else:
            for i in range(self.num_envs):
                self._core.reset_env(i, self._obs)
        self._pending[:] = False
        self._any_pending = False
        self._on_reset(None)
        return self._obs.copy(), {}

    def step(self, actions):
        obs, rewards, terminated, truncated, infos = self._step(actions, self._obs)
        return obs.copy(), rewards, terminated, truncated, infos

    def step_into(self, actions, obs_out: np.ndarray):
        """:meth:`step` with the observations written straight into ``obs_out`` (float32, C-contiguous,
        (num_envs, obs_dim); a trainer's rollout row, say) and returned as they are: no copy.
        Non-finite actions raise ValueError from the C++ step, the one place they are checked.
        A subclass, or an instance, that overrides :meth:`step` (a wrapper that logs or slows
        steps) gets its own step called (and one copy)."""
        if type(self).step is not TargetVectorEnv.step or "step" in vars(self):
            obs, *rest = self.step(actions)
            obs_out[...] = obs
            return (obs_out, *rest)
        return self._step(actions, obs_out)

    def _step(self, actions, obs_out: np.ndarray):
        a = check_actions(actions, (self.num_envs, self.act_dim), finite=False)
        self._step_core(a, obs_out)
        if self._any_pending:  # NEXT_STEP: these envs were reset by this step
            resetting = self._pending.copy()
            self._on_reset(resetting)
            self._pending[:] = False
            self._any_pending = False
        terminated = self._terminated.astype(bool)
        truncated = self._truncated.astype(bool)
        infos: Dict[str, Any] = {}
        done = terminated | truncated
        if done.any():
            values = {
                "final_obs": np.where(done[:, None], self._final_obs, np.float32(0)),
                "success": self._success.astype(bool),
                "episode_return": np.where(done, self._ep_return, np.float32(0)),
                "episode_length": np.where(done, self._ep_length, np.int32(0)),
                "episode_frames": np.where(done, self._ep_frames, np.int64(0)),
            }
            values.update(self._task_infos(done))
            for key, value in values.items():
                infos[key] = value
                infos["_" + key] = done.copy()
            if self.autoreset_mode == AutoresetMode.NEXT_STEP:
                self._pending |= done
                self._any_pending = True
            else:
                self._on_reset(done)
        return obs_out, self._rewards.copy(), terminated, truncated, infos

    # -- inspection --------------------------------------------------------------------------
    @property
    def step_frames(self) -> np.ndarray:
        """Frames each env played in the last step (up to the frame that ended an episode)."""
        return self._step_frames.copy()

    def pop_match_stats(self) -> Dict[str, float]:
        """The decisions of every env since the last call (or since construction), then zeroes
        the sums: ``decisions`` (env steps), ``transitions`` (decisions whose match was not the
        current clip's continuation), ``cost_sum`` (their matched costs, normalized weighted
        feature space, summed) and ``frames`` (frames played, each step up to the frame that
        ended its episode). :mod:`mmrl.quality_log` turns them into training-log columns."""
        return {k: (float(v) if k == "cost_sum" else int(v)) for k, v in self._core.pop_match_stats().items()}

    def last_step_decision(self, i: int) -> Tuple[int, float]:
        """(match, cost) of env ``i``'s last step: the frame its match chose (what the full path
        plays) and the match's cost; kept through the autoreset, (-1, 0) after a reset."""
        match, cost = self._core.last_step_decision(int(i))
        return int(match), float(cost)

    def last_step_anchor(self, i: int) -> Tuple[float, float]:
        """(dx, dz) the root moved by at env ``i``'s last transition to keep the planted feet
        (character frame, meters; the arrive task's ``stand_anchor``), (0, 0) without one: what
        :meth:`mmrl.Character.play` takes as ``anchor``."""
        dx, dz = self._core.last_step_anchor(int(i))
        return float(dx), float(dz)

    def last_step_transition_cost(self, i: int) -> float:
        """The transition cost env i's last step matched with (a task may vary it per decision)."""
        return float(self._core.last_step_transition_cost(int(i)))

    def env_state(self, i: int) -> dict:
        """World-space state of env i: root x, z, yaw, database frame, target (and the task's own)."""
        return self._core.state(int(i))

    def current_frames(self) -> np.ndarray:
        """Each env's current database frame (int64, N)."""
        out = np.empty(self.num_envs, np.int64)
        self._core.current_frames(out)
        return out

    def observe(self, i: int) -> np.ndarray:
        """Env i's current observation, also written to the env's observation buffer."""
        out = np.empty(self.obs_dim, np.float32)
        self._core.observe(int(i), out)
        self._obs[i] = out
        return out

    def set_target(self, i: int, x: float, z: float) -> np.ndarray:
        """Move env i's target (world meters); returns its new observation."""
        self._core.set_target(int(i), float(x), float(z))
        return self.observe(i)

    def set_state(self, i: int, frame: int, x: float, z: float, yaw: float) -> np.ndarray:
        """Put env i's character on database ``frame`` at world (x, z) facing ``yaw`` (radians),
        keeping its target and episode; returns its new observation."""
        self._core.set_state(int(i), int(frame), float(x), float(z), float(yaw))
        return self.observe(i)


class SingleEnv(gym.Env):
    """One character of a task as a ``gymnasium.Env`` (the same C++ core with one env).

    Subclasses set ``vector_type``. ``info`` of a finished episode holds the vector env's
    per-episode infos as Python scalars; ``step_info_keys`` names per-step values read from
    the vector env after every step (e.g. ``hits``).
    """

    metadata = {"render_modes": [], "render_fps": 30}
    vector_type: Type[TargetVectorEnv] = TargetVectorEnv

    def __init__(self, *, db=None, data=None, config=None, render_mode: Optional[str] = None, **overrides):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self._vec = self.vector_type(1, db=db, data=data, config=config, num_threads=1, **overrides)
        self.db = self._vec.db
        self.config = self._vec.config
        self.render_mode = render_mode
        self.observation_space = self._vec.single_observation_space
        self.action_space = self._vec.single_action_space

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        super().reset(seed=seed)
        if seed is None and not self._vec._seeded:
            seed = int(self.np_random.integers(0, 2**63 - 1))
        obs, _ = self._vec.reset(seed=seed)
        return obs[0], {}

    def _step_info(self) -> Dict[str, Any]:
        return {}

    def step(self, action):
        a = check_actions(action, self.action_space.shape, finite=False)  # the C++ step checks finiteness
        obs, r, term, trunc, infos = self._vec.step(a[None])
        info: Dict[str, Any] = self._step_info()
        if term[0] or trunc[0]:
            obs = infos["final_obs"]
            for key, value in infos.items():
                if not key.startswith("_") and key != "final_obs":
                    info[key] = value[0].item()
        return obs[0].copy(), float(r[0]), bool(term[0]), bool(trunc[0]), info

    def env_state(self) -> dict:
        return self._vec.env_state(0)


# ----------------------------------------------------------------------------- the task record
@dataclass(frozen=True)
class TaskFlag:
    """A task-specific ``mmrl train`` switch, e.g. ``--no-hit-reward``: it sets ``option`` to
    ``value`` in the task's config (``target="config"``) or in the options handed to the
    task's ``callbacks`` (``target="callbacks"``, e.g. ``--no-curriculum``)."""

    flag: str
    option: str
    value: Any
    help: str
    target: str = "config"


@dataclass(frozen=True)
class Task:
    """Everything the commands, evaluation, rendering and export need to know of one task.

    Only ``name``, ``config_type``, ``vector_env`` and ``env`` are required.
    """

    name: str
    """The name on the command line (``mmrl train NAME``) and in ``config.json``."""
    config_type: type
    """The task's config dataclass (a :class:`TaskConfig`)."""
    vector_env: Type[TargetVectorEnv]
    env: type
    """The single-env class (``gymnasium.make``)."""
    gym_id: Optional[str] = None
    """Registered with gymnasium when set (e.g. ``mmrl/Plane-v0``)."""
    summary: str = ""
    """One line for ``mmrl train --help``."""
    ppo_defaults: Mapping[str, Any] = field(default_factory=dict)
    """PPOConfig fields this task trains best with (``--set`` overrides them)."""
    request_ppo_defaults: Mapping[str, Any] = field(default_factory=dict)
    """More PPOConfig fields for a new run conditioned on requests (``--request-groups``); --set overrides them."""
    presets: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    """``--preset NAME``: overrides of task options and PPOConfig fields."""
    default_preset: Optional[str] = None
    """The preset ``mmrl train`` applies to a new run when ``--preset`` is not given (one of
    ``presets``; None: the config classes' own defaults). The config classes themselves keep
    the paper's values, so ``--preset paper`` (an empty preset) is the paper's task."""
    flags: Tuple[TaskFlag, ...] = ()
    """Task-specific ``mmrl train`` switches."""
    policy_factory: Optional[Callable[[TargetVectorEnv], Callable[[int, int], Any]]] = None
    """``policy_factory(envs)(obs_dim, act_dim)``: a plug-in's actor-critic (None: rl.networks.TASK_NETWORKS')."""
    callbacks: Optional[Callable[[TargetVectorEnv, Mapping[str, Any]], Sequence[Any]]] = None
    """``callbacks(envs, options)``: trainer callbacks (e.g. a curriculum); ``options`` holds
    the ``mmrl train`` switches this task reads (``curriculum``)."""
    stages: int = 0
    """Curriculum stages (``--stage 1..stages`` for eval and render); 0 = none."""
    set_stage: Optional[Callable[[TargetVectorEnv, int], None]] = None
    """Put a vector env at stage k for its next resets."""
    outcomes: Tuple[str, ...] = ()
    """Episode outcomes besides success, as per-episode info keys and ``<key>_rate`` in the
    evaluation summary (``collision``; ``truncated`` is available to every task)."""
    scene: Optional[Callable[[TargetVectorEnv], Any]] = None
    """``scene(env)`` -> a recorder of what the full path draws besides the character (see
    ``mmrl.rollout.SceneRecorder``); None draws the character and targets only."""

    final_values: Optional[Callable[[Any, np.ndarray], Dict[str, float]]] = None
    """``final_values(layout, final_obs)``: per-episode numbers named ``final_...``, read from an
    episode's last observation (the arrive task's position and facing errors); ``mmrl eval``
    reports their median and p95 over the successful episodes."""
    rests: bool = False
    """Success is a rest (the arrive task; its config has ``hold_time``): ``mmrl eval`` also
    measures the motion while standing after each success (:mod:`mmrl.eval.standing`)."""
    check_data: Optional[Callable[[Any], None]] = None
    """``check_data(db)`` raises ValueError saying what the data lacks for this task, before
    ``mmrl train`` starts (the arrive task: data that can stop)."""

    training_config: Optional[Callable[[Any], Any]] = None
    """``training_config(config)`` -> the config the training envs run with, when it differs from
    the run's own (which evaluation, rendering, play and export use): e.g. the obstacles task
    trains without its collision-aware search when ``train_path_filter`` is off."""

    def train_config(self, config):
        """The config the training envs of a run with ``config`` use (``training_config``)."""
        return config if self.training_config is None or config is None else self.training_config(config)

    def make_vector_env(self, num_envs: int, *, db, config=None, num_threads: int = 0, **overrides):
        return self.vector_env(num_envs, db=db, config=config, num_threads=num_threads, **overrides)

    def default_config(self):
        return self.config_type()

    def config_from_dict(self, values: Mapping[str, Any], *, strict: bool = False):
        """The task's config from saved values (``config.json``); unknown keys are dropped unless
        ``strict`` (then TypeError); a retired option on: ValueError (``options.check_retired``)."""
        check_retired(self.config_type, values)
        names = {f.name for f in fields(self.config_type)}
        unknown = [k for k in values if k not in names and k not in self.config_type.retired]
        if unknown and strict:
            raise TypeError(f"unknown {self.name} option {unknown[0]!r}; options are {sorted(names)}")
        return self.config_type(**{k: v for k, v in values.items() if k in names})
