"""mmrl: motion matching driven by deep reinforcement learning.

Train character controllers that write motion-matching queries, in seconds on a CPU.
"""
from importlib.metadata import PackageNotFoundError, version as _version

from . import _core  # noqa: F401  (the C++ core)
from .bvh import BVHError, JointRoleError, Motion, load_bvh, parse_bvh
from .database import Database, DatabaseFileError
from .search import KDTree
from .ppo import CheckpointError, NonFiniteError, PPOConfig, TrainResult, load_policy, train
from .controller import Controller, StepResult
from . import metrics, policies  # noqa: F401
from . import synth, data  # noqa: F401
from .envs import register_envs as _register_envs

_register_envs()
from . import obstacles as _obstacles  # noqa: F401,E402  (registers mmrl/MovingObstacles-v0)

try:
    __version__ = _version("mmrl")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0+unknown"

__all__ = ["__version__", "BVHError", "JointRoleError", "Motion", "load_bvh", "parse_bvh", "Database",
           "DatabaseFileError", "KDTree", "PPOConfig", "TrainResult", "train",
           "load_policy", "CheckpointError", "NonFiniteError", "Controller", "StepResult", "metrics", "policies"]
