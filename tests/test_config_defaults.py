"""Python's task config dataclasses and the C++ config structs (tasks/task_config.hpp and each
task's) declare the same fields with the same defaults, and the constants Python uses come from
the C++ that defines them. Options are declared once, in the C++ table (name, default, range,
doc): the Python config is made from it, and every range is checked with one message."""
import dataclasses

import numpy as np
import pytest

import mmrl
from mmrl import _core


@pytest.mark.parametrize("task_name", ["plane", "obstacles"])
def test_python_and_cpp_config_defaults_agree(task_name):
    task = mmrl.get_task(task_name)
    py = task.config_type()
    cpp = task.vector_env.core_config_type()
    names = [f.name for f in dataclasses.fields(py) if f.name not in py.training_only]
    assert set(names) == set(cpp.field_names), (set(names) ^ set(cpp.field_names))
    for name in names:
        ours, theirs = getattr(py, name), getattr(cpp, name)
        if name == "clip_costs":  # a spec of clip names in Python, resolved to per-clip costs for C++
            assert ours == "" and list(theirs) == []
        elif name == "request_groups":  # "style,gait" in Python, a list of groups for C++
            assert ours == "" and list(theirs) == []
        elif isinstance(ours, bool) or isinstance(theirs, bool):
            assert bool(ours) == bool(theirs) and type(ours) is type(theirs), name
        else:
            assert np.float32(ours) == np.float32(theirs), (name, ours, theirs)


@pytest.mark.parametrize("task_name", ["plane", "obstacles"])
def test_every_option_has_a_doc_a_range_and_is_checked_against_it(task_name):
    """Each row of the table has a doc (the property's too, so the stub's); each numeric option
    just outside its range is refused naming it."""
    from mmrl.tasks.options import option_info

    task = mmrl.get_task(task_name)
    cfg = task.default_config()
    core = task.vector_env.core_config_type
    db = mmrl.default_database()
    assert [o[0] for o in core.options] == list(core.field_names)
    checked = 0
    for name in core.field_names:
        info = option_info(cfg, name)
        assert len(info.doc) > 20 and getattr(core, name).__doc__.startswith(info.doc[:20]), name
        if info.kind not in ("int", "float") or name in ("frames_per_step", "target_half_extent", "max_steps"):
            continue  # frames_per_step: the decision's own check; the others: cross-field or slow to reach
        step = 1 if info.kind == "int" else 1e-3
        bad = [info.low - step] if info.low > -np.inf else []
        bad += [info.high + step] if info.high < np.inf else []
        bad += [] if info.kind == "int" or info.inf_ok else [float("inf")]
        for value in bad:
            value = int(value) if info.kind == "int" else value
            with pytest.raises(ValueError, match=f"^{name} must be "):
                task.make_vector_env(1, db=db, config=cfg.replace(**{name: value}), num_threads=1)
            checked += 1
    assert checked >= (8 if task_name == "plane" else 35), checked


@pytest.mark.parametrize("name, value, message", [
    ("transition_cost", -1.0, "transition_cost must be finite and >= 0, got -1"),
    ("success_radius", 0.0, "success_radius must be finite and > 0, got 0"),
    ("request_any", 1.5, r"request_any must be in \[0, 1\], got 1.5"),
    ("success_bonus", float("nan"), "success_bonus must be finite, got nan"),
])
def test_the_range_messages(name, value, message):
    with pytest.raises(ValueError, match=f"^{message}$"):
        mmrl.get_task("plane").make_vector_env(1, db=mmrl.default_database(), num_threads=1, **{name: value})


def test_python_only_options_are_the_trainers():
    """A Python config declares only options the C++ core never sees (training_only)."""
    for task_name in ("plane", "obstacles"):
        task = mmrl.get_task(task_name)
        py = task.config_type
        names = {f.name for f in dataclasses.fields(py)}
        assert names - set(task.vector_env.core_config_type.field_names) == set(py.training_only)


@pytest.mark.parametrize("task_name", ["plane", "obstacles"])
def test_train_lists_every_option_with_its_default_range_and_doc(task_name, capsys):
    from mmrl.cli import main
    from mmrl.tasks.options import option_info

    assert main(["train", task_name, "--list-options"]) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    cfg = mmrl.get_task(task_name).default_config()
    assert [line.split()[0] for line in lines] == [f.name for f in dataclasses.fields(cfg)]
    for line in lines:
        name = line.split()[0]
        assert line.startswith(f"  {name} = {getattr(cfg, name)!r}"), line
        if name not in cfg.training_only:
            info = option_info(cfg, name)
            assert line.endswith(info.doc) and info.range_text() in line, line


def test_the_constants_python_uses_come_from_the_core():
    assert _core.TRAJECTORY_OFFSETS == (10, 20, 30)
    assert _core.MAX_FRAMES_PER_STEP == _core.TRAJECTORY_OFFSETS[-1]
    assert _core.MATCH_EXCLUDE_WINDOW == 20
    # The +30-frame sample's position and direction columns, against a hand-built feature row:
    # a clip walking straight along +Z at 1.2 m/s has its +30-frame position at (0, 1.2) and
    # faces (0, 1).
    db = mmrl.default_database()
    from mmrl.rl.policies import TRAJECTORY_FRAMES, database_speeds

    assert TRAJECTORY_FRAMES == _core.TRAJECTORY_OFFSETS
    p, d = _core.TRAJECTORY_POSITION_COLUMNS, _core.TRAJECTORY_DIRECTION_COLUMNS
    assert p == (15, 19, 23) and d == (17, 21, 25)
    f = db.features[db.valid_mask]
    assert np.allclose(np.hypot(f[:, d[2]], f[:, d[2] + 1]), 1.0, atol=1e-4)  # unit directions
    walk, run = database_speeds(db)
    assert 0.5 < walk < run < 5.0
    start, stop = db.clip_ranges[int(np.argmax(np.diff(db.clip_ranges, axis=1)))]
    assert stop - start > 100
    lo, hi = db.controller_windows(np.array([start + 50]))[0]  # the match's window, well inside a clip
    assert (lo, hi) == (start + 50 - _core.MATCH_EXCLUDE_WINDOW, start + 50 + _core.MATCH_EXCLUDE_WINDOW + 1)
