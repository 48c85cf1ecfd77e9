"""mmrl: motion matching driven by deep reinforcement learning.

Train character controllers that write motion-matching queries, in seconds on a CPU.
"""
import os as _os
from importlib.metadata import PackageNotFoundError, version as _version

# OpenMP threads that sleep while they wait, unless the user chose otherwise (set before torch,
# imported below, starts its OpenMP runtime). libgomp's default spins: two trainings sharing 2
# cores then ran 4.6x slower each; sleeping, 1.8x (the fair share is 2x), and a training alone
# is as fast (README, "Choices").
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from . import _core  # noqa: F401  (the C++ core)
from . import _compat

# The flat layout's module paths (mmrl.ppo, mmrl.database, ...) import for one more release, with a
# DeprecationWarning naming the new path (mmrl/_compat.py).
_compat.install()
from .motion.bvh import BVHError, JointRoleError, Motion, load_bvh, parse_bvh
from .motion.database import Database, DatabaseFileError
from .errors import InputError
from .motion.search import KDTree
from .rl.ppo import CheckpointError, NonFiniteError, PPOConfig, TrainResult, load_policy, train
from .character import Character, StepResult
from .motion.sources import default_database
from .tasks import Task, get_task, register_task, task_names  # registers mmrl/Plane-v0, mmrl/MovingObstacles-v0
from .runs import RunDir
from . import metrics, rollout  # noqa: F401
from .rl import policies  # noqa: F401
from .motion import synth, data  # noqa: F401


def __getattr__(name: str):  # mmrl.ppo as an attribute: the new module, with a warning
    return _compat.moved_attribute(name)


try:
    __version__ = _version("mmrl")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.0.0+unknown"

__all__ = ["__version__", "BVHError", "JointRoleError", "Motion", "load_bvh", "parse_bvh", "Database",
           "DatabaseFileError", "InputError", "KDTree", "PPOConfig", "TrainResult", "train", "load_policy",
           "CheckpointError", "NonFiniteError", "Character", "StepResult", "default_database", "Task", "get_task",
           "register_task", "task_names", "RunDir", "metrics", "policies", "rollout"]
