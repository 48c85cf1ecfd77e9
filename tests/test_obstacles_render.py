"""Moving obstacles on the full path: the 1-env fast env and the full-path controller agree
step for step; obstacle corners and per-frame motion match the env; eval JSON; videos; refused
options."""
import json

import imageio.v3 as iio
import numpy as np
import pytest

import mmrl
from mmrl.cli import main
from mmrl import default_database, get_task
from mmrl.rollout import FullPath, evaluate_full_path, follow
from mmrl.tasks.obstacles import ObstaclesVectorEnv
from mmrl.tasks.obstacles_scene import obstacle_corners

OBSTACLES = get_task("obstacles")


def evaluate_obstacles(db, policy, **kwargs):
    return evaluate_full_path(OBSTACLES, db, policy, **kwargs)


def follow_obstacles(db, policy, **kwargs):
    return follow(OBSTACLES, db, policy, **kwargs)
from mmrl.rl.policies import JoystickPolicy


@pytest.fixture(scope="module")
def db():
    return default_database()


@pytest.fixture(scope="module")
def normal_db(shared_data):
    return mmrl.Database.from_bvh(sorted((shared_data / "normal").glob("*.bvh"))[:40])


def run_lockstep(db, steps, seed, stage=10):
    """Joystick actions with random perturbations (to force transitions); checks every step."""
    rng = np.random.default_rng(seed)
    run = FullPath(OBSTACLES, db, stage=stage, seed=seed, scene=True)
    joy = JoystickPolicy.preset(db, "joystick").bind_layout(run.env.observation_layout)
    low, high = run.env.single_action_space.low, run.env.single_action_space.high
    ends = {"success": 0, "collision": 0}
    checked = 0
    for _ in range(steps):
        a = joy.act(run.obs[None])[0] + rng.normal(0, 0.5, 12).astype(np.float32)
        a = np.clip(a, low, high).astype(np.float32)
        # Where the env says its obstacles will be after the step's frames (its own motion rule).
        predicted = run.env.obstacles_after(0, run.config.frames_per_step)
        out = run.step(a)
        if out["done"]:
            # The episode's last root (at the ending frame) is the controller's shown one.
            assert out["goal_error"] < 1e-4
            assert 1 <= out["step_frames"] <= run.config.frames_per_step
            ends["success"] += out["success"]
            ends["collision"] += out["collision"]
            continue
        frame_diff, root_diff = run.root_error()
        assert frame_diff == 0 and root_diff < 1e-5
        # Hit points are those the env stored for the step's action.
        st = run.env.env_state(0)
        np.testing.assert_allclose(st["hit_points"], out["hit_points"], atol=1e-6)
        assert tuple(out["hit_inside"]) == st["hit_inside"]
        # The predicted per-frame obstacle motion ends where the env's obstacles are.
        after = run.env.obstacles(0)
        np.testing.assert_allclose(predicted["centres"], after["centres"], atol=1e-5)
        np.testing.assert_array_equal(predicted["velocities"], after["velocities"])
        checked += 1
    return checked, ends


def test_env_and_controller_roots_agree_synthetic(db):
    checked, ends = run_lockstep(db, 300, seed=3)
    assert checked > 200 and ends["collision"] > 0


def test_env_and_controller_roots_agree_shared_data(normal_db):
    checked, ends = run_lockstep(normal_db, 150, seed=4, stage=5)
    assert checked > 100 and ends["success"] + ends["collision"] > 0


def test_obstacle_corners_match_the_env_inside_test(db):
    env = ObstaclesVectorEnv(1, db=db, num_threads=1, body_radius=0.0)
    env.reset(seed=0)
    centres = np.array([[1.0, 2.0], [-3.0, 0.5]], np.float32)
    half = np.array([[1.0, 0.3], [0.4, 0.8]], np.float32)
    angles = np.array([0.6, 2.2], np.float32)
    env._core.set_obstacles(0, centres, half, angles, np.zeros((2, 2), np.float32))
    corners = obstacle_corners(env.obstacles(0))
    for k in range(2):
        np.testing.assert_allclose(corners[k].mean(0), centres[k], atol=1e-6)
        for c in corners[k]:
            inner = centres[k] + 0.98 * (c - centres[k])
            outer = centres[k] + 1.02 * (c - centres[k])
            assert env._core.collides(0, float(inner[0]), float(inner[1]))
            assert not env._core.collides(0, float(outer[0]), float(outer[1]))


def test_joystick_reads_the_target_of_obstacle_observations(db):
    maps = (("maps", 512), ("pose", 15), ("goal", 2))
    plane = (("pose", 15), ("goal", 2))
    obstacles, on_plane = (JoystickPolicy.preset(db, "joystick").bind_layout(layout) for layout in (maps, plane))
    obs = np.random.default_rng(0).normal(size=(5, 529)).astype(np.float32)
    np.testing.assert_array_equal(obstacles.act(obs), on_plane.act(obs[:, -17:]))
    # A request code (docs/styles.md) may follow either observation: the goal stays where it was.
    coded = np.concatenate([obs, np.ones((5, 9), np.float32)], 1)
    np.testing.assert_array_equal(obstacles.act(coded), obstacles.act(obs))
    np.testing.assert_array_equal(on_plane.act(coded[:, -26:]), on_plane.act(obs[:, -17:]))
    with pytest.raises(ValueError, match="expected shape"):
        obstacles.act(obs[:, :500])  # ends before the layout's goal
    # Deprecated for one release: a joystick bound to no layout tells the two built-in tasks
    # apart by the observation's length, and says so.
    joy = JoystickPolicy.preset(db, "joystick")
    with pytest.warns(DeprecationWarning, match="bind the joystick"):
        np.testing.assert_array_equal(joy.act(obs), joy.act(obs[:, -17:]))
        np.testing.assert_array_equal(joy.act(coded), joy.act(obs))
        np.testing.assert_array_equal(joy.act(coded[:, -26:]), joy.act(obs[:, -17:]))
        np.testing.assert_array_equal(joy.act(obs), obstacles.act(obs))
    with pytest.raises(ValueError, match="expected shape"):
        joy.act(obs[:, :10])  # shorter than any task's observation
    from mmrl.rl.policies import goal_offset

    with pytest.warns(DeprecationWarning, match="observation_layout"):
        assert (goal_offset(529), goal_offset(17)) == (527, 15)  # after the maps and the pose features


def test_evaluate_obstacles_counts_outcomes(db):
    res = evaluate_obstacles(db, JoystickPolicy.preset(db, "joystick"), episodes=6, seed=1, stage=10)
    eps = res["episode_results"]
    assert len(eps) == 6
    for e in eps:  # every episode ends in exactly one way
        assert e["success"] + e["collision"] + e["truncated"] == 1
    assert res["collision_rate"] == pytest.approx(np.mean([e["collision"] for e in eps]))
    assert res["success_rate"] + res["collision_rate"] + res["truncation_rate"] == pytest.approx(1.0)
    # The same seed gives the same episodes.
    again = evaluate_obstacles(db, JoystickPolicy.preset(db, "joystick"), episodes=6, seed=1, stage=10)
    assert [e["steps"] for e in again["episode_results"]] == [e["steps"] for e in eps]


def test_eval_json_keys_match_the_plane_task_plus_collision_rate(capsys):
    assert main(["eval", "--policy", "joystick", "--episodes", "1", "--line", "0", "--json"]) == 0
    plane = json.loads(capsys.readouterr().out)
    assert main(["eval", "--task", "obstacles", "--policy", "joystick", "--episodes", "3", "--stage", "2",
                 "--json"]) == 0
    obst = json.loads(capsys.readouterr().out)
    assert set(plane) <= set(obst)
    assert set(obst) - set(plane) == {"collision_rate", "truncation_rate", "stage"}
    assert obst["env"] == "obstacles" and obst["stage"] == 2 and obst["episodes"] == 3


@pytest.mark.parametrize("argv, message", [
    (["--task", "obstacles", "--stage", "0"], "--stage must be in 1..10"),
    (["--task", "obstacles", "--stage", "11"], "--stage must be in 1..10"),
    (["--stage", "3"], "--stage applies to --task obstacles only"),
])
def test_bad_stage_is_refused(argv, message, capsys, tmp_path):
    for cmd in (["eval", "--episodes", "1"], ["render", "-o", str(tmp_path / "x.gif")]):
        assert main(cmd + argv) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "x.gif").exists()


def test_rendered_obstacles_gif_reads_back(tmp_path, capsys):
    out, still = tmp_path / "obst.gif", tmp_path / "still.png"
    assert main(["render", "--task", "obstacles", "--stage", "4", "--length", "1.5", "--size", "160x96",
                 "--seed", "2", "-o", str(out), "--still", str(still)]) == 0
    assert "stage 4, episodes:" in capsys.readouterr().out
    frames = iio.imread(out, index=None)
    assert frames.shape[0] >= 45 and frames.shape[1:3] == (96, 160)
    diffs = [np.abs(frames[i + 1].astype(int) - frames[i]).mean() for i in range(frames.shape[0] - 1)]
    assert np.count_nonzero(diffs) > 0.8 * len(diffs)
    assert iio.imread(still).shape == (96, 160, 3)


def test_obstacles_change_the_picture(db):
    """The same motion rendered with and without the obstacles, sensors and hit points differs."""
    from mmrl.viz.render import render_video

    rec = follow_obstacles(db, JoystickPolicy.preset(db, "joystick"), seconds=0.5, seed=0, stage=10)
    plain = {k: v for k, v in rec.items() if k not in ("obstacles", "sensor_maps", "sensor_positions",
                                                       "hit_inside", "episode")}
    assert rec["obstacles"].shape == (rec["frames"].size, 100, 4, 2)
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        render_video(Path(d) / "a.gif", rec, db, width=160, height=96, still=Path(d) / "a.png", still_frame=3)
        render_video(Path(d) / "b.gif", plain, db, width=160, height=96, still=Path(d) / "b.png", still_frame=3)
        a, b = iio.imread(Path(d) / "a.png"), iio.imread(Path(d) / "b.png")
    assert np.abs(a.astype(int) - b).mean() > 1.0
