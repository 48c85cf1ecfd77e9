"""bench/soak.py (issue 18, item 3) at a tiny scale: every part runs and writes its RSS CSV and
verdict line; the verdict's slope against lines of known slope. The full soak (10M steps per
task, 30 minutes of training and of play) is on demand: bench/README.md."""
import csv
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

SOAK = Path(__file__).resolve().parents[1] / "bench" / "soak.py"


def _soak_module():
    spec = importlib.util.spec_from_file_location("soak", SOAK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("slope, expected", [(0.0, "FLAT"), (5.0, "FLAT"), (60.0, "GROWING"), (-60.0, "SHRINKING")])
def test_verdict_fits_the_slope_of_the_last_two_thirds(slope, expected):
    soak = _soak_module()
    # A warm-up jump of 300 MB in the first third, then a line of `slope` MB/hour, over an hour.
    samples = [(t, 100.0 + (300.0 if t > 600 else 0.0) + slope * t / 3600.0, 0) for t in range(0, 3601, 5)]
    line = soak.verdict("x", samples, threshold_mb_per_h=20.0)
    assert float(re.search(r"slope of the last 2/3: ([-+0-9.]+) MB/h", line).group(1)) == pytest.approx(slope, abs=0.1)
    assert line.endswith(expected)


def test_every_part_runs_at_a_tiny_scale(tmp_path):
    out = tmp_path / "soak"
    done = subprocess.run([sys.executable, str(SOAK), "all", "--scale", "0.0005", "--interval", "0.1", "--out",
                           str(out), "--envs", "64", "--port", "8391"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    summary = (out / "soak_summary.txt").read_text()
    for task in ("plane", "obstacles"):
        steps = int(re.search(rf"soak env {task}: ([0-9,]+) steps", summary).group(1).replace(",", ""))
        assert steps >= 5000
    assert "soak train plane:" in summary and "(mmrl train exit 0)" in summary
    frames = int(re.search(r"soak play plane: ([0-9,]+) frames", summary).group(1).replace(",", ""))
    assert frames >= 10
    assert len(re.findall(r"^soak (env plane|env obstacles|train plane|play plane): (RSS|\d+ RSS samples)",
                          summary, re.M)) == 4
    for name in ("soak_env_plane", "soak_env_obstacles", "soak_train", "soak_play"):
        rows = list(csv.DictReader((out / f"{name}.csv").read_text().splitlines()))
        assert rows and all(float(r["rss_mb"]) > 0 for r in rows)
        assert max(float(r["rss_mb"]) for r in rows) > 50  # numpy, torch and the database are in


def test_live_session_timing_stays_bounded(monkeypatch):
    # The soak of `mmrl play` found RSS growing by 23 MB/hour: the timing lists kept every sample.
    import mmrl
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.viewer import live

    monkeypatch.setattr(live, "TIMING_SAMPLES", 5)
    db = mmrl.default_database()
    task = mmrl.get_task("plane")
    session = live.LiveSession(task, db, JoystickPolicy.preset(db, "joystick"), config=task.default_config())
    for k in range(6 * 20):
        if k % 12 == 0:
            session.set_target(3.0 * (k % 24 == 0) - 1.5, 2.0)
        session.step()
    assert session.decisions >= 20
    assert all(len(samples) <= 5 for samples in session.timing.values())
    assert len(session.timing["policy"]) == 5 and session.timing_ms()["policy"] > 0
    session.close()


def test_obstacle_env_keeps_a_bounded_record_of_finished_episodes(monkeypatch):
    # The env soak found RSS growing by 177 MB/hour: an obstacles env stepped without a
    # curriculum draining pop_finished_episodes kept every finished episode.
    import numpy as np

    import mmrl
    from mmrl.tasks.obstacles import ObstaclesVectorEnv

    monkeypatch.setattr(ObstaclesVectorEnv, "MAX_FINISHED_EPISODES", 20)
    env = mmrl.get_task("obstacles").make_vector_env(16, db=mmrl.default_database(), num_threads=1)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    ended = 0
    for _ in range(300):
        _, _, terminated, truncated, infos = env.step(rng.uniform(low, high, (16, low.size)).astype(np.float32))
        ended += int((terminated | truncated).sum())
    assert ended > 20
    stages, success = env.unwrapped.pop_finished_episodes()
    assert len(stages) == len(success) == 20  # the last 20
    assert len(env.unwrapped.pop_finished_episodes()[0]) == 0
    env.close()
