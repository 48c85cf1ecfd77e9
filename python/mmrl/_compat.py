"""The module paths of the flat layout (mmrl 0.1), importable for one more release.

``import mmrl.ppo`` still works and gives the very module ``mmrl.rl.ppo`` (same classes, same
functions, so pickles and ``mock.patch("mmrl.ppo.train")`` keep working), with a
``DeprecationWarning`` naming the new path. No shim files: a finder on ``sys.meta_path``
answers for the old names only, and ``mmrl.__getattr__`` does the same for ``mmrl.ppo`` used as
an attribute. Remove this module (and its two hooks in ``mmrl/__init__.py``) in the next release.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType
from typing import Optional

#: Old module path -> new module path.
MOVED = {
    **{f"mmrl.{m}": f"mmrl.motion.{m}" for m in ("bvh", "data", "database", "search", "sources", "synth",
                                                 "synth_motion")},
    **{f"mmrl.{m}": f"mmrl.rl.{m}" for m in ("checkpoints", "networks", "policies", "ppo", "quality_log",
                                             "trained_policy")},
    # The metrics log and progress bar serve every training (PPO and the compressed networks').
    "mmrl.logger": "mmrl.logs", "mmrl.rl.logger": "mmrl.logs",
    **{f"mmrl.{m}": f"mmrl.export.{m}" for m in ("runtime_export", "runtime_file")},
    "mmrl.integrations.onnx_export": "mmrl.export.onnx_export",
    **{f"mmrl.{m}": f"mmrl.viz.{m}" for m in ("camera", "plots", "render")},
    "mmrl.controller": "mmrl.character",
    "mmrl.reference": "mmrl.eval.reference", "mmrl.rl.reference": "mmrl.eval.reference",  # mmrl.Controller is mmrl.Character (one name per concept)
}

#: Old public names -> (module, new name): ``mmrl.Controller`` is ``mmrl.Character``.
RENAMED = {"Controller": ("mmrl.character", "Character")}


def _warn(old: str, new: str, stacklevel: int) -> None:
    warnings.warn(f"{old} is deprecated and will be removed in the next release; import {new} instead",
                  DeprecationWarning, stacklevel=stacklevel + 1)


class _AliasLoader(importlib.abc.Loader):
    """Loads an old name as the module of its new name (no second copy of the module)."""

    def __init__(self, new: str):
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        # stacklevel 2 is the importer: the warnings module skips the import machinery's frames.
        _warn(spec.name, self.new, 2)
        module = importlib.import_module(self.new)
        self._spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = self._spec  # the import system set the alias's spec on the real module


class _AliasFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname: str, path=None, target=None) -> Optional[importlib.machinery.ModuleSpec]:
        new = MOVED.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(new))


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once), ahead of any stale file of an old name."""
    if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder())


def moved_attribute(name: str) -> ModuleType:
    """``mmrl.<name>`` for an old top-level module name (``mmrl.__getattr__``); AttributeError otherwise."""
    if name in RENAMED:
        module, new_name = RENAMED[name]
        _warn(f"mmrl.{name}", f"{module}.{new_name} (mmrl.{new_name})", 3)
        return getattr(importlib.import_module(module), new_name)
    new = MOVED.get(f"mmrl.{name}")
    if new is None:
        raise AttributeError(f"module 'mmrl' has no attribute {name!r}")
    _warn(f"mmrl.{name}", new, 3)
    return importlib.import_module(new)
