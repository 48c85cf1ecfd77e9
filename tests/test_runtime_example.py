"""examples/runtime (mmrl_runtime_example): the C++ program writes the JSON trace of
``mmrl play --trace``, one line per decision per character, equal to the same characters
driven through the runtime's binding. CI builds it (.ci/run); elsewhere the test looks in
build/*/ or $MMRL_RUNTIME_EXAMPLE and skips if it is not built."""
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.export.runtime_export import write_controller
from mmrl.tasks.plane import PlaneConfig
from mmrl.viewer.live import LiveSession
from runtime_helpers import built_artifact
from test_runtime import random_obstacle_policy, random_plane_policy

TARGETS = [(0.0, 3.0), (3.0, 3.0), (3.0, -2.0), (-2.0, 0.0)]


def example_binary() -> Path:
    return built_artifact("MMRL_RUNTIME_EXAMPLE", "mmrl_runtime_example", "MMRL_BUILD_EXAMPLES=ON")


@pytest.fixture(scope="module")
def controller(tmp_path_factory):
    path = tmp_path_factory.mktemp("example") / "plane.mmrl"
    write_controller(path, mmrl.default_database(), random_plane_policy(2), "plane", PlaneConfig(transition_cost=5.0))
    return path


def reference_trace(path, characters, decisions, request=""):
    """The example's loop through the binding (the same start frames, origins and target rule)."""
    c = _core.RuntimeController.load(str(path))
    db = mmrl.default_database()
    valid = np.flatnonzero(db.valid_mask)
    lines = []
    chars = []
    for i in range(characters):
        origin = np.array([2.0 * (i % 8), 2.0 * (i // 8)], np.float32)
        ch = _core.RuntimeCharacter(c, float(origin[0]), float(origin[1]), 0.0, int(valid[(i * 97) % len(valid)]))
        ch.set_target(*(origin + np.float32(TARGETS[0])))
        if request:
            ch.set_request(request)
        chars.append([ch, origin, 0])
    for _ in range(decisions):
        for i, entry in enumerate(chars):
            ch, origin, k = entry
            root = ch.root
            target = origin + np.float32(TARGETS[k % len(TARGETS)])
            if np.hypot(float(target[0]) - root[0], float(target[1]) - root[1]) < 0.5:
                entry[2] = k = k + 1
                ch.set_target(*(origin + np.float32(TARGETS[k % len(TARGETS)])))
            for _ in range(6):
                ch.update(1.0 / 30.0)
            d = ch.last_decision()
            lines.append({"character": i, "t": d["frames_before"] / 30.0, "root": list(d["root_before"]),
                          "target": list(d["target"]), "frame": d["match"], "transition": d["transition"]})
    return lines


def test_example_writes_the_play_trace(controller, tmp_path):
    trace = tmp_path / "trace.jsonl"
    targets = ";".join(f"{x},{z}" for x, z in TARGETS)
    done = subprocess.run([str(example_binary()), str(controller), "--characters", "3", "--decisions", "150",
                           "--targets", targets, "--trace", str(trace)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "us per character per frame" in done.stderr
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    ref = reference_trace(controller, 3, 150)
    assert len(lines) == len(ref) == 450
    for got, want in zip(lines, ref):
        assert got["character"] == want["character"] and got["frame"] == want["frame"], (got, want)
        assert got["transition"] == want["transition"]
        assert got["t"] == pytest.approx(want["t"], abs=1e-4)
        np.testing.assert_allclose(got["root"], want["root"], atol=1e-5)
        np.testing.assert_allclose(got["target"], want["target"], atol=1e-5)
    assert sum(line["transition"] for line in lines) >= 10
    # The keys of mmrl play --trace (viewer/live.py), plus "character".
    play = tmp_path / "play.jsonl"
    session = LiveSession(mmrl.get_task("plane"), mmrl.default_database(), random_plane_policy(2), trace=str(play))
    for _ in range(7):
        session.step()
    session.close()
    assert set(lines[0]) == set(json.loads(play.read_text().splitlines()[0])) | {"character"}


def test_example_keeps_to_a_request(controller, tmp_path):
    trace = tmp_path / "walk.jsonl"
    targets = ";".join(f"{x},{z}" for x, z in TARGETS)
    done = subprocess.run([str(example_binary()), str(controller), "--characters", "2", "--decisions", "100",
                           "--targets", targets, "--request", "gait=run", "--trace", str(trace)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    ref = reference_trace(controller, 2, 100, request="gait=run")
    assert [(x["character"], x["frame"]) for x in lines] == [(x["character"], x["frame"]) for x in ref]
    db = mmrl.default_database()
    run = db.clip_tags[:, db.tag_names.index("gait=run")]
    assert run[db.frame_clip[[x["frame"] for x in lines]]].all()
    bad = subprocess.run([str(example_binary()), str(controller), "--request", "gait=fly"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "no tag 'gait=fly'" in bad.stderr and "gait=run|walk" in bad.stderr


def test_example_refuses_a_bad_file_with_one_line(tmp_path):
    bad = tmp_path / "bad.mmrl"
    bad.write_bytes(b"MMRLCTRL" + bytes(20))
    done = subprocess.run([str(example_binary()), str(bad)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().startswith("mmrl_runtime_example: error: ") and str(bad) in done.stderr


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_prints_the_usage_and_exits_0(flag, controller):
    """--help and -h: the usage and every option on stdout, exit 0, nothing run (even beside a
    controller file); an unknown option stays an error naming it."""
    done = subprocess.run([str(example_binary()), str(controller), flag, "--trace", "/nonexistent/t.jsonl"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert done.stdout.startswith("usage: mmrl_runtime_example CONTROLLER")
    for option in ("--characters", "--decisions", "--targets", "--trace", "--request", "--obstacles", "-h, --help"):
        assert option in done.stdout, option
    alone = subprocess.run([str(example_binary()), flag], capture_output=True, text=True, timeout=60)
    assert alone.returncode == 0 and alone.stdout == done.stdout
    bad = subprocess.run([str(example_binary()), "--helpme"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "unknown option --helpme" in bad.stderr


def test_example_walks_an_obstacles_controller_through_a_crowd(controller, tmp_path):
    """--obstacles K: each character of an obstacles controller gets K moving rectangles before
    every decision, which change its decisions; a controller whose task has no obstacles refuses
    the flag with one line."""
    path = tmp_path / "obstacles.mmrl"
    config = mmrl.get_task("obstacles").default_config().replace(path_filter=True)
    write_controller(path, mmrl.default_database(), random_obstacle_policy(5), "obstacles", config)
    traces = {}
    for k in (0, 60):
        trace = tmp_path / f"crowd{k}.jsonl"
        done = subprocess.run([str(example_binary()), str(path), "--characters", "3", "--decisions", "40",
                               "--obstacles", str(k), "--trace", str(trace)], capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr
        traces[k] = [json.loads(line) for line in trace.read_text().splitlines()]
        assert len(traces[k]) == 3 * 40
    assert [x["frame"] for x in traces[0]] != [x["frame"] for x in traces[60]]
    bad = subprocess.run([str(example_binary()), str(controller), "--obstacles", "10"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "obstacles" in bad.stderr
