"""The type stub of the C++ extension (python/mmrl/_core.pyi) names everything the extension
exposes: every public class and function, and every public method and property of each class."""
import ast
import inspect
from pathlib import Path

import mmrl
from mmrl import _core


def _stub_names():
    stub = Path(mmrl.__file__).with_name("_core.pyi")
    assert stub.is_file(), f"{stub} is missing (tools/make_stubs.sh writes it)"
    tree = ast.parse(stub.read_text())
    top, members = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            top.add(node.name)
            members[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)} | {
                n.target.id for n in node.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)}
        elif isinstance(node, ast.FunctionDef):
            top.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            top.add(node.target.id)
        elif isinstance(node, ast.Assign):  # an alias such as the deprecated TargetTaskConfig = PlaneTaskConfig
            for t in node.targets:
                if isinstance(t, ast.Name):
                    top.add(t.id)
                    if isinstance(node.value, ast.Name) and node.value.id in members:
                        members[t.id] = members[node.value.id]
    return top, members


def test_stub_names_every_public_name_of_the_extension():
    top, members = _stub_names()
    public = {n for n in dir(_core) if not n.startswith("_")}
    assert public - top == set(), "run tools/make_stubs.sh: the stub misses these names"
    for name in public:
        obj = getattr(_core, name)
        if inspect.isclass(obj) and not issubclass(obj, BaseException):
            own = {n for n in vars(obj) if not n.startswith("_")}
            missing = own - members.get(name, set())
            assert not missing, f"run tools/make_stubs.sh: the stub of {name} misses {sorted(missing)}"
