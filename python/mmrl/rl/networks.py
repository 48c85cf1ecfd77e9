"""The paper's policy and value networks (section 5, Figure 3).

Every actor-critic here has the interface ``mmrl.rl.ppo`` relies on:

- ``actor_mean(obs) -> (B, act_dim)``: the mean of the Gaussian policy, with
  no tanh squashing; the env clips actions to its box.
- ``value(obs) -> (B,)``: the state value.
- ``log_std``: a learnable, state-independent log standard deviation per
  action dimension. The paper does not say; RLlib's default (the authors')
  makes it a network output, but a free parameter is the common choice for
  PPO on continuous control, is cheaper, and keeps exploration from collapsing
  in states the value function has not seen yet.
- ``init_kwargs``: the constructor arguments, saved in checkpoints so
  ``mmrl.rl.ppo.load_policy`` can rebuild the network without the env.

Loading a checkpoint never imports code: a checkpoint names its network, and only classes
in this module's registry can be built. The paper's networks are registered here; register
your own with ``register_network(MyActorCritic)`` (usable as a class decorator) before
loading a checkpoint that uses it.

Policy and value networks never share weights, as in the paper.
Observations arrive already normalized by PPO (see ``PPOConfig.obs_norm``).
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Optional, TypeVar

import torch
from torch import nn

from .. import _core

__all__ = ["PlaneActorCritic", "MLPActorCritic", "ObstacleActorCritic", "OBSTACLE_DEFAULT_LAYOUT", "register_network",
           "registered_networks", "network_class", "network_name"]

# ----------------------------------------------------------------------------- registry

_NETWORKS: dict[str, type] = {}
NetworkClass = TypeVar("NetworkClass", bound=type)


def _class_path(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def register_network(cls: NetworkClass, name: Optional[str] = None) -> NetworkClass:
    """Let checkpoints that name ``cls`` be loaded; returns ``cls`` (so it works as a decorator).

    ``name`` (default: the class's qualified name) is what new checkpoints store. Registering
    the same name again for the same class (e.g. after a module reload) is allowed; for a
    different class it is an error.
    """
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise TypeError(f"register_network: expected a torch.nn.Module subclass, got {cls!r}")
    missing = [method for method in ("actor_mean", "value") if not callable(getattr(cls, method, None))]
    if missing:
        raise TypeError(f"register_network: {cls.__qualname__} lacks {', '.join(missing)} (see mmrl.rl.networks)")
    name = cls.__qualname__ if name is None else str(name)
    if not name or ":" in name:
        raise ValueError(f"register_network: invalid name {name!r} (non-empty, no ':')")
    previous = _NETWORKS.get(name)
    if previous is not None and _class_path(previous) != _class_path(cls):
        raise ValueError(f"register_network: {name!r} is already registered for {_class_path(previous)}")
    _NETWORKS[name] = cls
    return cls


def registered_networks() -> list[str]:
    """The names of all registered network classes, sorted."""
    return sorted(_NETWORKS)


def network_class(stored_name: str) -> type:
    """The registered class a checkpoint's ``model_class`` names: a registered name, or the
    "module:qualname" form older checkpoints store (e.g. "mmrl.networks:PlaneActorCritic", from
    before the subpackages: the flat layout's module paths are translated), matched against the
    registered classes. Never imports anything; raises ``KeyError`` for any other name."""
    from .._compat import MOVED

    if stored_name in _NETWORKS:
        return _NETWORKS[stored_name]
    module, sep, qualname = stored_name.partition(":")
    if sep and module in MOVED:
        stored_name = f"{MOVED[module]}:{qualname}"
    for cls in _NETWORKS.values():
        if _class_path(cls) == stored_name:
            return cls
    raise KeyError(stored_name)


def network_name(model: nn.Module) -> str:
    """What a checkpoint stores for ``model``: its registered name, else "module:qualname"
    (which loads once that class is registered)."""
    for name, cls in _NETWORKS.items():
        if type(model) is cls:
            return name
    return _class_path(type(model))


# ----------------------------------------------------------------------------- building blocks


def _linear(in_features: int, out_features: int, gain: float = math.sqrt(2)) -> nn.Linear:
    """A linear layer with orthogonal weights and zero bias (the usual PPO init)."""
    layer = nn.Linear(in_features, out_features)
    nn.init.orthogonal_(layer.weight, gain)
    nn.init.zeros_(layer.bias)
    return layer


def _mlp(in_features: int, hidden: tuple[int, ...], out_features: int, out_gain: float,
         activation: type[nn.Module]) -> nn.Sequential:
    layers: list[nn.Module] = []
    width = in_features
    for size in hidden:
        layers += [_linear(width, size), activation()]
        width = size
    layers.append(_linear(width, out_features, out_gain))
    return nn.Sequential(*layers)


@register_network
class PlaneActorCritic(nn.Module):
    """Plane task: policy MLP 32 x 32 tanh -> action mean; value MLP 32 x 32 tanh -> 1.

    obs = [c_t (15 pose features), g_t (2, target in the character frame, m)],
    but any flat observation works. The policy's last layer starts near zero
    (gain 0.01) so the first actions are centred in the action box.
    """

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...] = (32, 32),
                 init_log_std: float = 0.0):
        super().__init__()
        self.init_kwargs = dict(obs_dim=obs_dim, act_dim=act_dim, hidden=tuple(hidden),
                                init_log_std=init_log_std)
        self.actor = _mlp(obs_dim, tuple(hidden), act_dim, 0.01, nn.Tanh)
        self.critic = _mlp(obs_dim, tuple(hidden), 1, 1.0, nn.Tanh)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))

    def actor_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return self.actor(obs)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)


@register_network
class MLPActorCritic(nn.Module):
    """An actor and a critic MLP of their own sizes on the whole flat observation.

    The actor is what gets exported (ONNX, the C++ runtime's dense evaluator), so it can stay
    small; the critic is only used in training and may be wider. On the moving-obstacles task
    (``--set network=mlp``): actor 64 x 64, critic 128 x 128, ReLU, on the 529 observation floats
    (the binary maps flattened): about 39k actor weights against the paper's CNN's 573k, 4x the
    training steps per second (bench/bench_obstacles_learner.py), but far less learned per step
    (docs/obstacles.md, "The learner").
    """

    def __init__(self, obs_dim: int, act_dim: int, actor_hidden: tuple[int, ...] = (64, 64),
                 critic_hidden: tuple[int, ...] = (128, 128), activation: str = "relu",
                 init_log_std: float = 0.0):
        super().__init__()
        acts = {"relu": nn.ReLU, "tanh": nn.Tanh}
        if activation not in acts:
            raise ValueError(f"MLPActorCritic: activation must be one of {sorted(acts)}, got {activation!r}")
        self.init_kwargs = dict(obs_dim=obs_dim, act_dim=act_dim, actor_hidden=tuple(actor_hidden),
                                critic_hidden=tuple(critic_hidden), activation=activation,
                                init_log_std=init_log_std)
        self.actor = _mlp(obs_dim, tuple(actor_hidden), act_dim, 0.01, acts[activation])
        self.critic = _mlp(obs_dim, tuple(critic_hidden), 1, 1.0, acts[activation])
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))

    def actor_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return self.actor(obs)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)


#: Default flat-obs layout of the moving-obstacles task: name and size of each
#: consecutive segment. "maps" is the two 16 x 16 binary sensor maps as
#: (channel, row, col) in C order, channel 0 the current map and channel 1 the
#: previous one; then c_t (15 pose features) and g_t (2, target in meters in the
#: character frame).
OBSTACLE_DEFAULT_LAYOUT: tuple[tuple[str, int], ...] = (("maps", 2 * 16 * 16), ("pose", 15), ("goal", 2))


class _ObstacleTower(nn.Module):
    """conv C1@4x4 -> conv C2@3x3 (stride 1, no padding) -> FC F; concat the vector part;
    FC H1 -> ... -> head. ReLU throughout (the paper does not name the activation). The paper's
    sizes: C = (16, 32), F = 128, H = (256, 128)."""

    def __init__(self, map_shape: tuple[int, int, int], vector_dim: int, out_features: int,
                 out_gain: float, channels: tuple[int, int] = (16, 32), map_features: int = 128,
                 head: tuple[int, ...] = (256, 128)):
        super().__init__()
        in_channels, height, width = map_shape
        c1, c2 = (int(c) for c in channels)
        self.conv = nn.Sequential(
            nn.Conv2d(in_channels, c1, 4, stride=1), nn.ReLU(),
            nn.Conv2d(c1, c2, 3, stride=1), nn.ReLU(),
            nn.Flatten(),
        )
        conv_out = c2 * (height - 3 - 2) * (width - 3 - 2)
        for module in self.conv:
            if isinstance(module, nn.Conv2d):
                nn.init.orthogonal_(module.weight, math.sqrt(2))
                nn.init.zeros_(module.bias)
        self.map_fc = nn.Sequential(_linear(conv_out, int(map_features)), nn.ReLU())
        self.head = _mlp(int(map_features) + vector_dim, tuple(int(h) for h in head), out_features, out_gain, nn.ReLU)

    def forward(self, maps: torch.Tensor, vector: torch.Tensor) -> torch.Tensor:
        features = self.map_fc(self.conv(maps))
        return self.head(torch.cat([features, vector], dim=-1))


@register_network
class ObstacleActorCritic(nn.Module):
    """Moving-obstacles task: a CNN tower for the policy; for the value, another tower (the
    paper's) or an MLP on the flat observation (``critic_hidden``).

    The observation is one flat float vector; ``layout`` names its consecutive
    segments and sizes (default ``OBSTACLE_DEFAULT_LAYOUT``: 512 map entries,
    then 15 pose, then 2 goal). The segment named "maps" is reshaped to
    ``map_shape`` (C, H, W); every other segment is concatenated, in layout
    order, into the vector that joins after the map's FC layer. Pass the
    env's layout here if it differs.

    The defaults are the paper's network. ``channels``, ``map_features`` and ``head`` size the
    actor's tower (and the critic's, without ``critic_hidden``); only the actor is exported,
    so a small actor is what the runtime pays for, while the critic (training only) may be
    larger than it.

    PPO should leave the binary maps unnormalized: pass
    ``PPOConfig(obs_norm_exclude=ObstacleActorCritic.map_range(layout))``.
    """

    def __init__(self, act_dim: int, layout: tuple[tuple[str, int], ...] = OBSTACLE_DEFAULT_LAYOUT,
                 map_shape: tuple[int, int, int] = (2, 16, 16), init_log_std: float = 0.0,
                 channels: tuple[int, int] = (16, 32), map_features: int = 128,
                 head: tuple[int, ...] = (256, 128), critic_hidden: Optional[tuple[int, ...]] = None):
        super().__init__()
        layout = tuple((str(name), int(size)) for name, size in layout)
        names = [name for name, _ in layout]
        if names.count("maps") != 1:
            raise ValueError(f"ObstacleActorCritic: layout needs exactly one 'maps' segment, got {names}")
        map_start, map_stop = self.map_range(layout)
        if map_stop - map_start != math.prod(map_shape):
            raise ValueError(f"ObstacleActorCritic: 'maps' segment has {map_stop - map_start} entries "
                             f"but map_shape {tuple(map_shape)} needs {math.prod(map_shape)}")
        tower = dict(channels=tuple(int(c) for c in channels), map_features=int(map_features),
                     head=tuple(int(h) for h in head))
        self.init_kwargs = dict(act_dim=act_dim, layout=layout, map_shape=tuple(map_shape),
                                init_log_std=init_log_std, **tower,
                                critic_hidden=None if critic_hidden is None else tuple(int(h) for h in critic_hidden))
        self.obs_dim = sum(size for _, size in layout)
        self.map_shape = tuple(map_shape)
        self._map_slice = slice(map_start, map_stop)
        # Vector segments: everything but the maps, in layout order. Usually one
        # contiguous run after the maps, which makes the split a cheap view.
        vector_idx = [i for i in range(self.obs_dim) if not map_start <= i < map_stop]
        self._vector_contiguous = vector_idx == list(range(vector_idx[0], vector_idx[-1] + 1)) if vector_idx else True
        self._vector_slice = slice(vector_idx[0], vector_idx[-1] + 1) if vector_idx else slice(0, 0)
        self.register_buffer("_vector_index", torch.tensor(vector_idx, dtype=torch.long), persistent=False)
        vector_dim = len(vector_idx)
        self.actor = _ObstacleTower(self.map_shape, vector_dim, act_dim, 0.01, **tower)
        self._critic_mlp = critic_hidden is not None
        if self._critic_mlp:
            self.critic = _mlp(self.obs_dim, tuple(int(h) for h in critic_hidden), 1, 1.0, nn.ReLU)
        else:
            self.critic = _ObstacleTower(self.map_shape, vector_dim, 1, 1.0, **tower)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))

    @staticmethod
    def map_range(layout: tuple[tuple[str, int], ...] = OBSTACLE_DEFAULT_LAYOUT) -> tuple[int, int]:
        """(start, stop) of the "maps" segment in the flat observation."""
        start = 0
        for name, size in layout:
            if name == "maps":
                return start, start + int(size)
            start += int(size)
        raise ValueError(f"layout has no 'maps' segment: {layout}")

    def _split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if obs.shape[-1] != self.obs_dim:
            raise ValueError(f"ObstacleActorCritic: expected obs with {self.obs_dim} entries, got {tuple(obs.shape)}")
        maps = obs[:, self._map_slice].reshape(obs.shape[0], *self.map_shape)
        if self._vector_contiguous:
            vector = obs[:, self._vector_slice]
        else:
            vector = obs.index_select(1, self._vector_index)
        return maps, vector

    def actor_mean(self, obs: torch.Tensor) -> torch.Tensor:
        return self.actor(*self._split(obs))

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        if self._critic_mlp:
            if obs.shape[-1] != self.obs_dim:
                raise ValueError(f"ObstacleActorCritic: expected obs with {self.obs_dim} entries, got {tuple(obs.shape)}")
            return self.critic(obs).squeeze(-1)
        return self.critic(*self._split(obs)).squeeze(-1)


# ------------------------------------------------------------------------------------------
# The networks a task trains with (tasks name none of them: rl comes after tasks)
# ------------------------------------------------------------------------------------------
#: The networks ``obstacle_policy_factory`` builds (``--set network=NAME``; "default" is "cnn").
OBSTACLE_NETWORKS = ("cnn", "small-cnn", "mlp")
#: "small-cnn": the paper's tower with conv 8@4x4, conv 8@3x3, FC 64, head 64 (about 66k actor
#: weights against 573k), and an MLP critic 128 x 128 on the flat observation.
SMALL_CNN = dict(channels=(8, 8), map_features=64, head=(64,), critic_hidden=(128, 128))


def obstacle_policy_factory(envs=None, network: str = "default"):
    """``policy_factory(obs_dim, act_dim)`` for ``ppo.train``: "cnn" (the default) is the paper's
    CNN actor-critic (:class:`ObstacleActorCritic`) with this env's observation
    layout; "small-cnn" the same tower with an eighth of the actor's weights and an MLP critic
    (``--preset mmrl-small``); "mlp" is ``MLPActorCritic`` (actor 64 x 64, critic 128 x 128, ReLU)
    on the flat observation."""
    layout = getattr(envs, "layout", OBSTACLE_DEFAULT_LAYOUT)
    map_shape = getattr(envs, "map_shape", (2, _core.OBSTACLE_MAP_SIDE, _core.OBSTACLE_MAP_SIDE))
    network = "cnn" if network == "default" else network
    if network not in OBSTACLE_NETWORKS:
        raise ValueError(f"network: the obstacles task builds {', '.join(OBSTACLE_NETWORKS)} (or default), "
                         f"got {network!r}")

    def factory(obs_dim: int, act_dim: int):
        if obs_dim != sum(size for _, size in layout):
            raise ValueError(f"obstacle_policy_factory: obs_dim {obs_dim} does not match the layout {layout}")
        if network == "mlp":
            return MLPActorCritic(obs_dim, act_dim)
        small = SMALL_CNN if network == "small-cnn" else {}
        return ObstacleActorCritic(act_dim, layout=layout, map_shape=map_shape, **small)

    return factory


#: Task name -> its ``policy_factory(envs, network=...)``; a task absent here (and without its
#: own ``Task.policy_factory``) trains PPO's default MLP.
TASK_NETWORKS: Dict[str, Callable[..., Callable[[int, int], nn.Module]]] = {"obstacles": obstacle_policy_factory}


def task_policy_factory(task) -> Optional[Callable[..., Callable[[int, int], nn.Module]]]:
    """The factory a task's policy is built by: the task's own (a plug-in's), else the one
    registered for its name in :data:`TASK_NETWORKS`, else None (PPO's default)."""
    return task.policy_factory or TASK_NETWORKS.get(task.name)
