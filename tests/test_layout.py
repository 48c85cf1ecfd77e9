"""The package layout (issue 23): subpackages by concern, no import circles, and the flat
layout's module paths still importable for one release.

The import graph is read from the source, not from a running interpreter: every ``import`` and
``from ... import`` in ``python/mmrl/**/*.py``, at module level or inside functions and
``TYPE_CHECKING`` blocks alike (a function-level import is a circle that only waits for its
call). An edge goes from a module to each mmrl module it names; ``from PKG import NAME`` names
``PKG.NAME`` when that is a module, else ``PKG``. Parent packages run first on any import, but an
edge to them is not drawn (every module would then depend on ``mmrl/__init__``).
"""
from __future__ import annotations

import ast
import importlib
import sys
import warnings
from pathlib import Path
from typing import Dict, List, Set

import pytest
import torch

import mmrl
from mmrl import _compat

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "mmrl"


# ------------------------------------------------------------------------------------------
# The import graph and its circles
# ------------------------------------------------------------------------------------------
def module_names(package_dir: Path) -> Dict[str, Path]:
    """{dotted module name: file} for every ``.py`` file under ``package_dir`` (a package's
    ``__init__.py`` is the package's own name), and every ``.pyi`` stub of an extension
    (``_core``: it imports nothing of ours)."""
    out = {}
    for path in sorted(package_dir.rglob("*.py")) + sorted(package_dir.rglob("*.pyi")):
        parts = (package_dir.name,) + path.relative_to(package_dir).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.setdefault(".".join(parts), path)
    return out


def import_graph(package_dir: Path) -> Dict[str, Set[str]]:
    """{module: the package's modules it imports}, from every import statement in its source."""
    modules = module_names(package_dir)
    graph: Dict[str, Set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        here = name.split(".") if is_package else name.split(".")[:-1]
        if path.suffix == ".pyi":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: List[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = here[:len(here) - (node.level - 1)] + ([node.module] if node.module else [])
                    source = ".".join(base)
                else:
                    source = node.module or ""
                named = [f"{source}.{a.name}" for a in node.names if f"{source}.{a.name}" in modules]
                targets = named + ([source] if len(named) < len(node.names) else [])
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    found: List[List[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def test_cycles_against_hand_made_graphs():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": {"e"}, "e": {"d"}, "f": set()}) == [
        ["a", "b", "c"], ["d", "e"]]


def test_import_graph_reads_function_level_and_relative_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .sub import mod\n")
    (pkg / "sub" / "__init__.py").write_text("from .. import _ext\n")
    (pkg / "_ext.pyi").write_text("from pkg import other\n")  # a stub: no edges
    (pkg / "sub" / "mod.py").write_text("import os\nfrom typing import TYPE_CHECKING\n"
                                        "if TYPE_CHECKING:\n    from ..other import X\n")
    (pkg / "other.py").write_text("def f():\n    from .sub.mod import g\n    from . import sub\n")
    assert import_graph(pkg) == {"pkg": {"pkg.sub.mod"}, "pkg.sub": {"pkg._ext"}, "pkg._ext": set(), "pkg.sub.mod": {"pkg.other"},
                                 "pkg.other": {"pkg.sub.mod", "pkg.sub"}}
    assert cycles(import_graph(pkg)) == [["pkg.other", "pkg.sub.mod"]]


def test_no_import_circles_in_mmrl():
    graph = import_graph(PACKAGE)
    assert "mmrl.rl.ppo" in graph and "mmrl.rl.checkpoints" in graph["mmrl.rl.ppo"]
    assert cycles(graph) == [], "import circles (move what both sides need into a module both import)"


# ------------------------------------------------------------------------------------------
# Rooms in layers: a room imports only rooms of its own layer or below
# ------------------------------------------------------------------------------------------
#: The package's rooms (a subpackage, or a top-level module) by layer, lowest first. The motion
#: layer is the data and the two motion sources (the database, the compressed networks) and the
#: character that plays them; tasks decide and reward; rl trains; eval measures; viz, viewer and
#: export show and ship; integrations and commands drive everything. ``mmrl/__init__`` (the
#: public names) and ``__main__`` sit above all.
LAYERS = (
    {"_core", "_compat", "errors", "io", "arrays", "logs"},
    {"motion", "character", "compress", "metrics"},
    {"tasks"},
    {"rl"},
    {"eval", "rollout", "runs"},
    {"viz", "viewer", "export"},
    {"integrations"},
    {"commands"},
    {"cli"},
    {"mmrl", "__main__"},
)


def room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "mmrl"


def layering_violations(graph: Dict[str, Set[str]], layers=LAYERS) -> List[str]:
    """Every import of a module from a higher layer's room (function-level imports count). The
    package itself (``from . import __version__``) is no edge: it runs before any of its modules."""
    level = {r: k for k, rooms in enumerate(layers) for r in rooms}
    return sorted(f"{a} -> {b}" for a, targets in graph.items() for b in targets
                  if "." in b and level[room(a)] < level[room(b)])


def test_layering_against_a_hand_made_graph():
    layers = ({"a"}, {"b"}, {"c"})
    graph = {"pkg.a.x": {"pkg.b.y", "pkg"}, "pkg.b.y": {"pkg.a.z"}, "pkg.a.z": set(), "pkg.c": {"pkg.a.x", "pkg.b.y"}}
    assert layering_violations(graph, layers) == ["pkg.a.x -> pkg.b.y"]


def test_every_room_imports_only_its_layer_and_below():
    graph = import_graph(PACKAGE)
    rooms = {room(m) for m in graph}
    assert rooms <= set().union(*LAYERS), f"rooms without a layer: {sorted(rooms - set().union(*LAYERS))}"
    assert layering_violations(graph) == [], "an import up the layers (inject it, or move the code down)"


# ------------------------------------------------------------------------------------------
# The layout itself
# ------------------------------------------------------------------------------------------
#: The top folder keeps the cross-cutting modules only; everything else sits in a subpackage.
TOP_LEVEL = {"__init__", "__main__", "_compat", "arrays", "cli", "character", "errors", "io", "logs", "metrics",
             "rollout", "runs"}


def test_top_folder_holds_only_cross_cutting_modules_and_no_shims():
    assert {p.stem for p in PACKAGE.glob("*.py")} == TOP_LEVEL
    assert (PACKAGE / "_core.pyi").is_file()  # the stub stays beside the extension
    for old in _compat.MOVED:  # no file left at an old path
        assert not (ROOT / "python" / (old.replace(".", "/") + ".py")).exists(), old


# ------------------------------------------------------------------------------------------
# The old module paths: deprecated aliases of the same modules
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("old", sorted(_compat.MOVED))
def test_old_module_path_imports_the_new_module_with_a_warning(old, monkeypatch):
    new = _compat.MOVED[old]
    module = importlib.import_module(new)
    parent, _, attr = old.rpartition(".")
    monkeypatch.delitem(sys.modules, old, raising=False)
    parent_module = importlib.import_module(parent)
    if attr in vars(parent_module):
        monkeypatch.delattr(parent_module, attr)
    with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated.*import {new} instead"):
        aliased = importlib.import_module(old)
    assert aliased is module and sys.modules[old] is module
    assert module.__spec__.name == new and module.__name__ == new  # the real module's identity is kept
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert importlib.import_module(old) is module  # once imported, no second warning


def test_old_names_give_the_same_objects(monkeypatch):
    from mmrl.rl.ppo import PPOConfig, train
    from mmrl.motion.database import Database

    for old in ("mmrl.ppo", "mmrl.database"):
        monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match="mmrl.rl.ppo"):
        from mmrl.ppo import PPOConfig as OldConfig, train as old_train
    with pytest.warns(DeprecationWarning, match="mmrl.motion.database"):
        from mmrl.database import Database as OldDatabase
    assert (OldConfig, old_train, OldDatabase) == (PPOConfig, train, Database)


def test_old_top_level_attribute_warns_and_public_names_do_not():
    monkeypatch = pytest.MonkeyPatch()
    try:
        monkeypatch.delattr(mmrl, "checkpoints", raising=False)
        with pytest.warns(DeprecationWarning, match="mmrl.checkpoints is deprecated.*mmrl.rl.checkpoints"):
            assert mmrl.checkpoints is importlib.import_module("mmrl.rl.checkpoints")
    finally:
        monkeypatch.undo()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in mmrl.__all__:
            getattr(mmrl, name)
        assert mmrl.policies is importlib.import_module("mmrl.rl.policies")
        assert mmrl.synth is importlib.import_module("mmrl.motion.synth")
        assert mmrl.data is importlib.import_module("mmrl.motion.data")
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        mmrl.nonexistent  # noqa: B018


# ------------------------------------------------------------------------------------------
# Saved files name no module paths
# ------------------------------------------------------------------------------------------
def _strings(value) -> List[str]:
    if isinstance(value, str):
        return [value]
    if isinstance(value, dict):
        return [s for k, v in value.items() for s in _strings(k) + _strings(v)]
    if isinstance(value, (list, tuple)):
        return [s for v in value for s in _strings(v)]
    return []


def test_a_checkpoint_and_config_json_name_no_module_paths(tmp_path):
    """A checkpoint names its network by its registered name, and config.json names the task:
    a run written before or after a module moves loads the same (checked on a fresh training)."""
    from mmrl.cli import main
    from mmrl.rl.checkpoints import load_checkpoint
    from mmrl.rl.networks import PlaneActorCritic, network_class

    run = tmp_path / "run"
    assert main(["train", "plane", "--steps", "256", "--envs", "4", "--no-progress", "--out", str(run),
                 "--set", "num_steps=64"]) == 0
    state = load_checkpoint(run / "latest.pt")
    assert state["model_class"] == "PlaneActorCritic" and network_class("PlaneActorCritic") is PlaneActorCritic
    stored = _strings(state) + _strings(mmrl.RunDir(run).config)
    assert stored and not [s for s in stored if "mmrl." in s or "mmrl/" in s], stored
    with open(run / "latest.pt", "rb") as f:  # nor does the pickle stream (weights-only: no globals of ours)
        assert b"mmrl." not in f.read()
    assert isinstance(mmrl.load_policy(run / "latest.pt").model, PlaneActorCritic)
    assert torch.is_tensor(state["model"]["log_std"])


def test_this_releases_renamed_names_warn_and_are_the_same_objects(monkeypatch):
    from mmrl.compress import model
    from mmrl.rollout import FullPath

    with pytest.warns(DeprecationWarning, match="use CompressedModel"):
        assert model.CompressedController is model.CompressedModel
    path = FullPath.__new__(FullPath)
    path.character = object()
    with pytest.warns(DeprecationWarning, match="FullPath.character"):
        assert path.ctrl is path.character
