"""How a task's env draws itself (gymnasium's ``env.render()``) without importing the drawing
code: tasks come before viz in the package's layering (tests/test_layout.py), so
:mod:`mmrl.viz.render` registers its drawings here when it is imported, and a task asks for one
by name. Asked before viz was imported, the registry imports it by name: the drawings are the
``mmrl[viz]`` extra, loaded only when something is drawn."""
from __future__ import annotations

import importlib
from typing import Callable, Dict

DRAWINGS: Dict[str, Callable] = {}
DRAWING_MODULE = "mmrl.viz.render"


def register_drawing(name: str, draw: Callable) -> None:
    DRAWINGS[name] = draw


def drawing(name: str) -> Callable:
    """The drawing registered as ``name`` (``"topdown"``: many envs from above; ``"state"``: one
    env's character)."""
    if name not in DRAWINGS:
        importlib.import_module(DRAWING_MODULE)
    return DRAWINGS[name]
