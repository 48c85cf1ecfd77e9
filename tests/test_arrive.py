"""The arrive task (issue 38; a plug-in core of the rebuild, issue 37): its success rule against a
frame-by-frame reference over the full path's own roots, its facing observation against a hand
computation, its facing at the runtime, the data it refuses, the motion kinds ``db info`` reports,
and the commands that run it (train, eval, render, runtime and ONNX export)."""
import json
import math
import warnings

import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.motion.bvh import MotionImportWarning
from mmrl.export.runtime_export import write_controller
from mmrl.motion.kinds import check_can_stop, motion_kinds
from mmrl.rollout import FullPath
from test_runtime import random_plane_policy

ARRIVE = mmrl.get_task("arrive")


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_success_is_a_hold_at_rest_facing_the_target_frame_by_frame():
    """Every step of 600: the env ends an episode exactly where a Python reference over the
    character's played roots completes hold_time of consecutive frames within success_radius,
    facing_tolerance and with the root's velocity, exponentially smoothed over a quarter second,
    below stop_speed (the hold carries across steps, restarts with an episode), and the facing segment of each observation is (sin, cos) of the facing in the
    character frame."""
    db = mmrl.default_database()
    config = ARRIVE.default_config().replace(success_radius=1.5, stop_speed=1.0, facing_tolerance=1.2,
                                             hold_time=0.2, target_half_extent=2.5, min_target_distance=1.6,
                                             max_steps=30, precision_weight=2.0, facing_weight=0.5)
    fp = FullPath(ARRIVE, db, config=config, seed=3, record=False)
    H = fp.env._core.hold_frames
    assert H == round(0.2 * db.fps)
    rng = np.random.default_rng(1)
    from mmrl.rl.policies import JoystickPolicy, database_speeds

    policy = JoystickPolicy(db, database_speeds(db)[0], arrive=True)  # slows down at the target
    policy.bind_layout(fp.env.observation_layout)
    with pytest.raises(ValueError, match="goal and facing end"):
        policy.act(fp.obs[None, :18])  # ends inside the facing: one clear error, not numpy's
    hold = successes = 0
    velocity = np.zeros(2)  # the root's smoothed world velocity (a time constant of 0.25 s), 0 at a start
    smoothing = 1 - math.exp(-1 / (0.25 * db.fps))
    goal = slice(15, 17)
    for _ in range(600):
        st = fp.env.env_state(0)
        facing, yaw = st["facing"], st["yaw"]
        np.testing.assert_allclose(fp.obs[17:19], [math.sin(facing - yaw), math.cos(facing - yaw)], atol=1e-6)
        assert np.linalg.norm(fp.obs[goal]) == pytest.approx(math.hypot(st["target"][0] - st["x"], st["target"][1] - st["z"]),
                                                              rel=1e-5)
        prev = np.array(fp.character.root, np.float64)
        action = policy.act(fp.obs[None])[0] if rng.random() < 0.7 else rng.normal(0, 1, 12).astype(np.float32)
        out = fp.step(action)
        roots = out["res"].roots
        expected_end = None
        for k in range(roots.shape[0]):
            r = roots[k]
            velocity += smoothing * ((r[:2] - prev[:2]) * db.fps - velocity)
            near = math.hypot(st["target"][0] - r[0], st["target"][1] - r[1]) <= config.success_radius
            facing_ok = abs(wrap(facing - r[2])) <= config.facing_tolerance
            hold = hold + 1 if near and facing_ok and np.hypot(*velocity) < config.stop_speed else 0
            prev = r
            if hold >= H:
                expected_end = k + 1
                break
        if expected_end is not None:
            assert out["terminated"] and out["step_frames"] == expected_end
            successes += 1
        else:
            assert not out["terminated"]
        # The reward where the step's played frames end (the hold's last frame on success).
        r = roots[out["step_frames"] - 1]
        d = math.hypot(st["target"][0] - r[0], st["target"][1] - r[1])
        e = abs(wrap(facing - r[2]))
        reward = math.exp(-d) + 0.5 * math.exp(-d / config.success_radius) * (1 + math.cos(e)) / 2
        if expected_end is not None:
            precision = (max(0.0, 1 - d / config.success_radius) + max(0.0, 1 - e / config.facing_tolerance)) / 2
            reward += config.success_bonus * (1 + 2.0 * precision)
        assert out["reward"] == pytest.approx(reward, rel=1e-4, abs=1e-4)
        if out["done"]:
            hold = 0
            velocity[:] = 0
    assert successes >= 5  # not vacuous


def test_the_runtime_needs_a_facing_in_radians():
    db = mmrl.default_database()
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "arrive.mmrl"
        write_controller(path, db, random_plane_policy(3, 19), "arrive", ARRIVE.default_config())
        controller = _core.RuntimeController.load(str(path))
    ch = _core.RuntimeCharacter(controller, 0.0, 0.0, 0.0, -1)
    assert ch.takes_facing
    ch.set_target(2.0, 1.0)
    with pytest.raises(ValueError, match="needs a facing: set it with set_facing \\(radians\\)"):
        ch.update(1.0 / 30.0)
    with pytest.raises(ValueError, match="finite"):
        ch.set_facing(float("inf"))
    ch.set_facing(math.pi / 2)
    obs = ch.observe()  # the facing in the character frame
    assert obs[17:19] == pytest.approx([math.sin(math.pi / 2 - ch.root[2]), math.cos(math.pi / 2 - ch.root[2])],
                                       abs=1e-5)
    ch.update(1.0 / 30.0)


def test_motion_kinds_on_clips_of_known_kind(tmp_path):
    """Standing, turning in place and walking clips of the synthetic data give the kinds they are:
    the fast turn in place (1.5 rad/s, 86 degrees a second) turns in place, the slow one (0.5
    rad/s, under the measure's 60 degrees) only stands."""
    from mmrl.motion import synth

    src = synth.default_dataset_dir()
    kinds = {}
    for name in ("stand", "turn-in-place-left", "walk"):
        files = sorted(src.glob(f"synth_*_{name}.bvh"))
        if name == "turn-in-place-left":
            assert len(files) == 2  # the plan's fast one first, the slow one last
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MotionImportWarning)
                kinds["slow-turn"] = motion_kinds(mmrl.Database.from_bvh(files[1:]))
            files = files[:1]
        with warnings.catch_warnings():  # a standing clip alone is slower than a person walks: the scale warning
            warnings.simplefilter("ignore", MotionImportWarning)
            kinds[name] = motion_kinds(mmrl.Database.from_bvh(files))
    assert kinds["stand"]["idle"] > 0.95
    assert kinds["turn-in-place-left"]["turn_in_place"] > 0.9
    assert kinds["slow-turn"]["idle"] > 0.9 and kinds["slow-turn"]["turn_in_place"] == 0.0
    assert kinds["walk"]["idle"] == 0.0 and kinds["walk"]["turn_in_place"] == 0.0
    assert kinds["walk"]["backwards"] == 0.0


def test_data_that_cannot_stop_is_refused_with_one_line(tmp_path, capsys):
    from mmrl.motion import synth

    walks = tmp_path / "walks"
    walks.mkdir()
    for f in synth.default_dataset_dir().glob("synth_*_walk*.bvh"):
        (walks / f.name).write_text(f.read_text())
    with pytest.raises(ValueError, match="cannot stop"):
        check_can_stop(mmrl.Database.from_bvh(walks))
    assert main(["train", "arrive", "--data", str(walks), "--steps", "2048", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "cannot stop" in err and "Traceback" not in err
    assert not (tmp_path / "run" / "latest.pt").exists()


def test_train_eval_render_and_export_through_the_cli(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "arrive", "--steps", "8192", "--out", str(run), "--no-progress"]) == 0
    assert json.loads((run / "config.json").read_text())["task"] == "arrive"
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "4", "--json", "--no-peer"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["env"] == "arrive" and res["episodes"] == 4
    for e in res["episode_results"]:  # the final errors, as the final observation tells them
        assert e["final_position_error_cm"] >= 0 and 0 <= e["final_facing_error_deg"] <= 180
        if e["success"]:
            assert e["final_position_error_cm"] <= 25.0 + 1e-3 and e["final_facing_error_deg"] <= 15.0 + 1e-3
    assert "final_position_error_cm_median" in res and "final_facing_error_deg_p95" in res
    assert main(["render", str(run), "--length", "0.4", "--size", "96x64", "-o", str(tmp_path / "a.gif")]) == 0
    assert (tmp_path / "a.gif").stat().st_size > 0
    assert main(["export", str(run), "-o", str(tmp_path / "a.mmrl")]) == 0
    c = _core.RuntimeController.load(str(tmp_path / "a.mmrl"))
    assert c.task_core == "arrive" and [name for name, _ in c.obs_layout] == ["pose", "goal", "facing"]
    pytest.importorskip("onnxruntime", reason="mmrl[onnx] is not installed (CI installs it)")
    assert main(["export", str(run), "--onnx", str(tmp_path / "a.onnx")]) == 0
    import onnxruntime

    session = onnxruntime.InferenceSession(str(tmp_path / "a.onnx"))
    obs = np.random.default_rng(0).normal(0, 1, (1, 19)).astype(np.float32)
    out = session.run(None, {session.get_inputs()[0].name: obs})[0]
    np.testing.assert_allclose(out[0], c.act(obs[0]), atol=1e-4)  # the same policy as the runtime file


def test_play_sets_the_facing_keeps_it_across_episodes_and_draws_its_arrow():
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.viewer.draw import LIFT, arrow
    from mmrl.viewer.live import LiveSession

    db = mmrl.default_database()
    s = LiveSession(ARRIVE, db, JoystickPolicy.preset(db, "joystick"))
    assert s.takes_facing and s.step()["facing"] == pytest.approx(s.run.env.env_state(0)["facing"])
    s.set_facing(1.0)
    for _ in range(12):
        shown = s.step()
    assert s.run.env.env_state(0)["facing"] == pytest.approx(1.0) and shown["facing"] == 1.0
    s.run.continue_from_character(s.run.target)  # what an ended episode does: the user's facing stays
    assert s.run.env.env_state(0)["facing"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="finite"):
        s.set_facing(float("nan"))
    plane = LiveSession(mmrl.get_task("plane"), db, JoystickPolicy.preset(db, "joystick"))
    assert not plane.takes_facing
    with pytest.raises(ValueError, match="reads none"):
        plane.set_facing(0.5)
    # The arrow: from the target along (sin yaw, cos yaw); yaw pi/2 points along +X.
    a = arrow((1.0, 2.0), math.pi / 2, 1.0)
    np.testing.assert_allclose(a[0], [[1.0, LIFT, 2.0], [2.0, LIFT, 2.0]], atol=1e-12)
    np.testing.assert_allclose(a[1:, 0], [[2.0, LIFT, 2.0]] * 2, atol=1e-12)
    assert np.all(a[1:, 1, 0] < 2.0)  # the barbs point back from the tip
