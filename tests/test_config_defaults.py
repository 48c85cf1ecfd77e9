"""Python's task config dataclasses and the C++ config structs (tasks/task_config.hpp and each
task's) declare the same fields with the same defaults, and the constants Python uses come from
the C++ that defines them."""
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
