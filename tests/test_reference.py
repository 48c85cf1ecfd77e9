"""The equal-speed reference (mmrl/eval/reference.py): joysticks at speeds spanning the data's gaits,
on the same episodes as the policy, read at the policy's own time to target."""
import json

import numpy as np
import pytest

import mmrl
from mmrl.eval.reference import MIN_GAIT_SPEED, against_line, joystick_line, joystick_speeds, line_value
from mmrl.rl.policies import JoystickPolicy, frame_speeds
from mmrl.rollout import evaluate_full_path
from test_import_axes_fps import other_skeleton_database


def row(t, v):
    return {"speed_m_per_s": 1.0, "mean_time_to_target_s": t, "foot_sliding_ik_off_cm_per_s": v}


def test_the_line_is_linear_in_time_and_holds_its_ends():
    line = [row(4.0, 20.0), row(2.0, 10.0), row(None, 99.0)]  # unordered; a joystick that never arrived
    assert line_value(line, 3.0) == pytest.approx(15.0)
    assert line_value(line, 2.5) == pytest.approx(12.5)
    assert line_value(line, 1.0) == pytest.approx(10.0)  # faster than the fastest: the fastest's value
    assert line_value(line, 9.0) == pytest.approx(20.0)  # slower than the slowest: the slowest's
    assert line_value(line, None) is None and line_value([row(None, 1.0)], 3.0) is None
    out = against_line({"mean_time_to_target_s": 3.0, "foot_sliding_ik_off_cm_per_s": 12.0}, line)
    assert out["joystick_line_sliding_ik_off_cm_per_s"] == pytest.approx(15.0)
    assert out["sliding_ik_off_vs_joystick_line"] == pytest.approx(0.8) and out["at_or_below_joystick_line"]
    out = against_line({"mean_time_to_target_s": 3.0, "foot_sliding_ik_off_cm_per_s": 18.0}, line)
    assert out["at_or_below_joystick_line"] is False


@pytest.mark.parametrize("which", ["synthetic", "mixamo"])
def test_speeds_span_the_data_s_gaits(which, tmp_path):
    db = mmrl.default_database() if which == "synthetic" else other_skeleton_database(tmp_path)
    speeds = joystick_speeds(db, 4)
    moving = frame_speeds(db)
    moving = moving[moving >= MIN_GAIT_SPEED]
    assert len(speeds) == 4 and np.all(np.diff(speeds) > 0)
    assert speeds[0] == pytest.approx(np.percentile(moving, 5)) and speeds[-1] == pytest.approx(np.percentile(moving, 95))
    assert (moving < speeds[0]).mean() == pytest.approx(0.05, abs=0.01)
    for bad in (1, 21, 2.5, True):
        with pytest.raises(ValueError, match="count"):
            joystick_speeds(db, bad)


def test_the_line_runs_each_joystick_on_the_policy_s_episodes_and_eval_reports_it(capsys):
    task, db = mmrl.get_task("plane"), mmrl.default_database()
    speeds = joystick_speeds(db, 3)
    line = joystick_line(task, db, speeds=speeds, episodes=4, seed=3)
    assert [r["speed_m_per_s"] for r in line] == speeds
    for speed, r in zip(speeds, line):  # each row is that joystick's own evaluation of the same episodes
        ref = evaluate_full_path(task, db, JoystickPolicy(db, speed, arrive=True), episodes=4, seed=3)
        assert r["foot_sliding_ik_off_cm_per_s"] == ref["foot_sliding_ik_off_cm_per_s"]
        assert r["mean_time_to_target_s"] == ref["mean_time_to_target_s"]
    assert all(r["success_rate"] == 1.0 for r in line)  # arriving joysticks do not circle the target
    times = [r["mean_time_to_target_s"] for r in line]
    assert times[0] > times[1] > times[2]  # faster joysticks arrive sooner
    from mmrl.cli import main

    assert main(["eval", "--episodes", "4", "--seed", "3", "--line", "3", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["joystick_line"] == line
    assert res["joystick_line_sliding_ik_off_cm_per_s"] == pytest.approx(line_value(line, res["mean_time_to_target_s"]))
    assert main(["eval", "--episodes", "2", "--line", "1"]) == 2
    assert "--line 1" in capsys.readouterr().err
    assert main(["eval", "--episodes", "2", "--task", "obstacles", "--json"]) == 0  # no line by default there
    assert "joystick_line" not in json.loads(capsys.readouterr().out)
