"""mmrl export-bvh / render / eval through the command line; BVH round trip; video read back."""
import json

import imageio.v2 as iio
import numpy as np
import pytest

import mmrl
from mmrl.cli import main


def read_video(path, width, height):
    """All frames of a video decoded by imageio-ffmpeg's ffmpeg (subprocess.run closes every pipe)."""
    import subprocess

    import imageio_ffmpeg

    out = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(path), "-f", "rawvideo",
                          "-pix_fmt", "rgb24", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(out, np.uint8).reshape(-1, height, width, 3)


def test_export_bvh_round_trip_synthetic(tmp_path, capsys):
    out = tmp_path / "gen.bvh"
    assert main(["export-bvh", "--length", "2", "--seed", "1", "-o", str(out)]) == 0
    m = mmrl.load_bvh(out)
    z = np.load(out.with_suffix(".npz"))
    assert m.num_frames == z["positions"].shape[0] == 1 + 10 * 6
    assert m.fps == pytest.approx(30.0, rel=1e-4)
    # The reloaded BVH reproduces the exported global positions (file units are written
    # with limited precision).
    np.testing.assert_allclose(m.global_positions(), z["positions"], atol=2e-4)
    assert list(z["joint_names"]) == m.joint_names


def test_export_bvh_on_shared_data(tmp_path, shared_data):
    out = tmp_path / "gen.bvh"
    data = sorted((shared_data / "normal").glob("*.bvh"))[:30]
    assert main(["export-bvh", "--data", *map(str, data), "--length", "3", "-o", str(out)]) == 0
    m = mmrl.load_bvh(out)
    z = np.load(out.with_suffix(".npz"))
    assert m.num_frames == z["positions"].shape[0] == 91
    np.testing.assert_allclose(m.global_positions()[:, 1:], z["positions"][:, 1:], atol=2e-4)


def test_render_mp4_shows_the_character_moving(tmp_path, shared_data):
    out = tmp_path / "walk.mp4"
    data = sorted((shared_data / "normal").glob("*.bvh"))[:30]
    assert main(["render", "--data", *map(str, data), "--length", "2", "-o", str(out),
                 "--size", "320x180", "--still", str(tmp_path / "still.png")]) == 0
    frames = read_video(out, 320, 180)
    assert len(frames) == 61 and frames[0].shape == (180, 320, 3)
    assert np.abs(frames[0].astype(np.int16) - frames[-1]).mean() > 1.0
    assert (tmp_path / "still.png").stat().st_size > 1000


def test_render_gif_and_bad_output(tmp_path):
    out = tmp_path / "a.gif"
    assert main(["render", "--length", "0.4", "-o", str(out), "--size", "160x90"]) == 0
    assert len(iio.mimread(str(out))) == 13
    assert main(["render", "--length", "1", "-o", str(tmp_path / "a.avi")]) == 2


def test_eval_json(capsys):
    assert main(["eval", "--episodes", "3", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    for k in ("success_rate", "mean_time_to_target_s", "foot_sliding_cm_per_s", "max_pose_jump_cm",
              "transitions_per_s"):
        assert k in res
    assert res["episodes"] == 3 and 0 <= res["success_rate"] <= 1


def test_run_directory_without_ppo_or_policy(tmp_path, capsys):
    (tmp_path / "config.json").write_text("{}")
    assert main(["eval", str(tmp_path), "--episodes", "1", "--policy", "joystick-run", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["policy"] == "joystick-run"
    assert main(["eval", str(tmp_path / "missing"), "--episodes", "1"]) == 2


def test_pose_bindings_refuse_bad_input():
    from mmrl import _core
    from mmrl import default_database

    db = default_database()
    J = db.num_joints
    t, r = np.zeros((2, J, 3), np.float32), np.tile(np.array([1, 0, 0, 0], np.float32), (2, J, 1))
    assert _core.motion_from_pose(db._db, t, r).num_frames == 2
    with pytest.raises(TypeError, match="float32"):
        _core.motion_from_pose(db._db, t.astype(np.float64), r)
    with pytest.raises(ValueError, match="dimension 0"):
        _core.motion_from_pose(db._db, t, r[:1])
    with pytest.raises(ValueError, match="NaN"):
        _core.motion_from_pose(db._db, t, np.full_like(r, np.nan))
    with pytest.raises(TypeError, match="int64"):
        _core.database_global_positions(db._db, np.zeros(3, np.int32))
    with pytest.raises(IndexError):
        _core.database_global_positions(db._db, np.array([db.num_frames], np.int64))


def test_set_deploys_a_task_option_for_one_command(tmp_path, capsys):
    """--set on the commands that run a trained controller: eval and export use the option (the
    transitions follow the transition cost; the exported file carries it), the run's config.json
    is kept, and a bad option is one line and exit 2."""
    from mmrl.export.runtime_file import read_sections

    run = tmp_path / "run"
    assert main(["train", "plane", "--steps", "256", "--envs", "4", "--out", str(run), "--no-progress"]) == 0
    saved = (run / "config.json").read_text()
    rates = {}
    for cost in ("0", "1000000"):
        capsys.readouterr()
        assert main(["eval", str(run), "--episodes", "3", "--json", "--no-peer", "--set", f"transition_cost={cost}"]) == 0
        rates[cost] = json.loads(capsys.readouterr().out)["transitions_per_s"]
    assert rates["1000000"] < rates["0"], rates
    out = tmp_path / "c.mmrl"
    assert main(["export", str(run), "-o", str(out), "--set", "transition_cost=123"]) == 0
    sections = read_sections(out)
    values = dict(zip(list(sections["task.keys"]), sections["task.values"]))
    assert values["transition_cost"] == 123.0
    assert (run / "config.json").read_text() == saved
    for command in (["eval", str(run), "--episodes", "1"], ["export", str(run), "-o", str(out)]):
        for bad, needle in (("transition_cost=-1", "transition_cost must be"), ("nope=1", "unknown option 'nope'"),
                            ("transition_cost", "KEY=VALUE"),
                            ("frames_per_step=3", "trained with frames_per_step=6")):
            capsys.readouterr()
            assert main(command + ["--set", bad]) == 2, (command, bad)
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and needle in err[0], err
    capsys.readouterr()  # a joystick has no trained inputs: it may run another step length
    assert main(["eval", "--episodes", "1", "--no-peer", "--json", "--set", "frames_per_step=3"]) == 0
