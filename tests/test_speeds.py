"""The walking and running speeds a database is read for (``mmrl.rl.policies.database_speeds``),
which the speed-preset joysticks walk at (``mmrl play --policy joystick``, the peers of
bench/bench_obstacles_goals.py): known answers on clips written at known speeds, invariance to
idle frames, and LAFAN1 (13% idle frames), whose estimate once was a 0.27 m/s 'walk'."""
import numpy as np
import pytest

import mmrl
from mmrl import synth
from mmrl.motion.bvh import MotionImportWarning
from mmrl.rl.policies import RUN_SPEED, database_speeds, frame_speeds

from conftest import require_lafan1


def _database(tmp_path, clips):
    for i, (speed, kind) in enumerate(clips):
        turn = 1.5 if kind == "turn" else 0.0
        synth.write_clip(tmp_path / f"c{i:02d}.bvh", speed=speed, turn_rate=turn, seconds=4.0, seed=i)
    return mmrl.Database.from_bvh(tmp_path)


def test_speeds_are_the_walks_and_the_runs_whatever_the_idle_frames(tmp_path):
    moving = [(1.2, "walk"), (1.2, "walk"), (1.4, "walk"), (3.0, "run")]
    idle = [(0.0, "stand"), (0.0, "turn"), (0.3, "walk")] * 2  # standing, turning in place, shuffling
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    walk, run = database_speeds(_database(tmp_path / "a", moving))
    assert walk == pytest.approx(1.2, rel=0.04) and run == pytest.approx(3.0, rel=0.04)  # the commanded speeds
    with_idle = _database(tmp_path / "b", moving + idle)
    assert (frame_speeds(with_idle) < 0.5).mean() > 0.5  # most frames idle: the old two-means walked at 0.3
    assert database_speeds(with_idle) == (walk, run)


def test_speeds_of_data_that_only_walks_or_only_stands(tmp_path):
    (tmp_path / "walks").mkdir(), (tmp_path / "stands").mkdir()
    db = _database(tmp_path / "walks", [(0.9, "walk"), (1.5, "walk")])
    walk, run = database_speeds(db)
    speeds = frame_speeds(db)
    assert walk == pytest.approx(np.median(speeds[speeds >= 0.5]))  # every frame walks
    assert run == pytest.approx(np.percentile(speeds[speeds >= 0.5], 90)) and walk < run < RUN_SPEED
    with pytest.warns(MotionImportWarning, match="median speed"):  # the import already doubts it
        stands = _database(tmp_path / "stands", [(0.0, "stand"), (0.0, "turn")])
    with pytest.raises(ValueError, match="no frame moving"):
        database_speeds(stands)


def test_lafan1_walks_at_a_walking_speed():
    """LAFAN1 (13% idle, 9% turns in place, 5% runs): walking about 0.9 m/s, running 2.5."""
    walk, run = database_speeds(mmrl.Database.from_bvh(require_lafan1("run")))
    assert 0.8 < walk < 1.1 and 2.2 < run < 2.8, (walk, run)
