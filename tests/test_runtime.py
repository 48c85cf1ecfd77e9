"""The C++ runtime (mmrl_runtime, cpp/include/mmrl/runtime.hpp) against Python's full path.

Given the same controller file, start and targets, the runtime and mmrl.rollout.FullPath (the
loop ``mmrl play`` runs) make the same decisions, show the same frames and roots, and the
same poses. The runtime's policy (policy_net.hpp) matches torch's within float rounding. A
character driven by a stick (set_stick) makes the decisions of the full path driven by the
scripted joystick (mmrl.rl.policies.JoystickPolicy) toward a target kept 1000 m along the stick.
"""
import copy

import numpy as np
import pytest
import torch

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.commands.export import sample_observations
from mmrl.rl.networks import PlaneActorCritic
from mmrl.rollout import FullPath
from mmrl.runs import RunDir
from mmrl.export.runtime_export import read_controller, write_controller
from mmrl.tasks.plane import PlaneConfig
from mmrl.rl.trained_policy import ObsNormalizer, Policy
from runtime_helpers import drive_both, drive_stick


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    """A plane run (the quality preset: a transition cost of 60) exported to a controller file."""
    out = tmp_path_factory.mktemp("runtime")
    run = out / "plane"
    assert main(["train", "plane", "--steps", "65536", "--seed", "0", "--out", str(run), "--no-progress"]) == 0
    assert main(["export", str(run), "-o", str(out / "plane.mmrl")]) == 0
    return run, out / "plane.mmrl"


def test_controller_file_round_trip(plane):
    run, path = plane
    db = RunDir(run).database()
    back = read_controller(path)
    for key in ("bone_translations", "bone_rotations", "root_positions", "root_yaws", "root_deltas", "contacts",
                "clip_ranges"):
        np.testing.assert_array_equal(getattr(back.db, key), getattr(db, key), err_msg=key)
    np.testing.assert_array_equal(back.db.normalized_features, db.normalized_features)
    np.testing.assert_array_equal(back.db.valid_mask, db.valid_mask)
    assert back.db.joint_names == db.joint_names and back.db.roles == db.roles and back.db.clip_names == db.clip_names
    assert back.task_name == "plane" and back.task["transition_cost"] == RunDir(run).task_config().transition_cost
    c = _core.RuntimeController.load(str(path))
    assert (c.num_frames, c.num_joints, c.obs_dim, c.task_name) == (db.num_frames, db.num_joints, 17, "plane")


def test_runtime_policy_matches_torch(plane):
    run, path = plane
    r = RunDir(run)
    policy, task = r.policy(), r.task
    obs = sample_observations(task, r.database(), r.task_config(task), policy, 1000, seed=5)
    c = _core.RuntimeController.load(str(path))
    ours = np.stack([c.act(o) for o in obs])
    ref = policy.act(obs)
    # Within 1e-5 of the action's magnitude (raw actions of a short training reach tens of units).
    assert np.max(np.abs(ours - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-5
    assert np.ptp(ref, axis=0).min() > 1e-3


def test_runtime_equals_python_full_path_for_1000_decisions(plane):
    """Both sides act with the runtime's own policy evaluation (bit-identical observations give
    bit-identical actions): the decisions, frames, roots and poses must agree exactly."""
    run, path = plane
    r = RunDir(run)
    c = _core.RuntimeController.load(str(path))
    db = read_controller(path).db
    out = drive_both(path, r.task, db, r.task_config(), c.act, 1000)
    assert out["obs_error"] == 0.0
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5 and out["pose_error"] <= 1e-4, out
    # Not vacuous: the character walked through many targets and changed clips.
    assert out["targets_reached"] >= 10
    assert np.count_nonzero(np.diff(out["py_matches"]) != 6) >= 20


def test_runtime_against_torch_policy_full_path(plane):
    """The Python full path acting with torch. The two policies differ by float rounding
    (about 1e-6), which flips a match only where two frames tie within that rounding: at most
    1% of the decisions may differ (measured: 1 in 1000 on two runs; the sequences agree again
    after it, the roots then differing by float rounding)."""
    run, path = plane
    r = RunDir(run)
    policy = r.policy()
    db = read_controller(path).db
    out = drive_both(path, r.task, db, r.task_config(), lambda o: policy.act(o[None])[0], 1000)
    same = np.mean(out["rt_matches"] == out["py_matches"])
    assert same >= 0.99, same


def random_plane_policy(seed: int, obs_dim: int = 17) -> Policy:
    torch.manual_seed(seed)
    model = PlaneActorCritic(obs_dim, 12)
    with torch.no_grad():
        model.actor[-1].weight.normal_(0, 0.5)
    norm = ObsNormalizer(obs_dim, True, None, 10.0, torch.device("cpu"))
    norm.rms.var = np.full(obs_dim, 4.0)
    norm.refresh()
    return Policy(model, norm, torch.device("cpu"))


def test_runtime_on_another_skeleton(tmp_path):
    """Mixamo names, other channel orders, meters: the same agreement with the full path."""
    from mmrl import synth
    from test_import_axes_fps import other_skeleton, read_clip

    paths = []
    for k, (speed, turn) in enumerate([(1.4, 0.3), (1.2, -0.5), (3.0, 0.2), (1.6, 0.0)]):
        synth.write_clip(tmp_path / f"c{k}.bvh", speed=speed, turn_rate=turn, seconds=8.0, seed=k)
        path = tmp_path / f"mixamo{k}.bvh"
        path.write_text(other_skeleton(read_clip((tmp_path / f"c{k}.bvh").read_text())).text())
        paths.append(path)
    db = mmrl.Database.from_bvh(paths, mirror=True)
    assert db.roles["left_foot"] == "mixamorig:LeftFoot"
    controller = tmp_path / "mixamo.mmrl"
    write_controller(controller, db, random_plane_policy(1), "plane", PlaneConfig(transition_cost=5.0))
    c = _core.RuntimeController.load(str(controller))
    out = drive_both(controller, mmrl.get_task("plane"), read_controller(controller).db,
                     PlaneConfig(transition_cost=5.0), c.act, 300)
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5 and out["pose_error"] <= 1e-4, out
    assert np.count_nonzero(np.diff(out["py_matches"]) != 6) >= 5


def random_obstacle_policy(seed: int, layout=None, **sizes) -> Policy:
    """A CNN policy with random weights for the obstacles task's observation (``layout``: an
    env's, e.g. with a request code; default the paper's 529 floats; ``sizes``: the network's
    channels, map_features, head)."""
    from mmrl.rl.networks import OBSTACLE_DEFAULT_LAYOUT, ObstacleActorCritic

    torch.manual_seed(seed)
    layout = tuple(layout or OBSTACLE_DEFAULT_LAYOUT)
    model = ObstacleActorCritic(12, layout=layout, **sizes)
    with torch.no_grad():
        model.actor.head[-1].weight.normal_(0, 0.3)
    norm = ObsNormalizer(model.obs_dim, True, ObstacleActorCritic.map_range(layout), 10.0, torch.device("cpu"))
    norm.refresh()
    return Policy(model, norm, torch.device("cpu"))


def test_runtime_cnn_policy_matches_torch(tmp_path):
    """The obstacles CNN in C++ (policy_net.cpp: the convolutions and dense layers add weight
    rows for their non-zero inputs only) against torch, on the task's own observations (sparse
    binary maps) and on dense random ones: within float rounding."""
    from mmrl.commands.export import sample_observations
    from mmrl.tasks.obstacles import ObstaclesConfig

    task, db = mmrl.get_task("obstacles"), mmrl.default_database()
    config = ObstaclesConfig(num_obstacles=60)
    obs = sample_observations(task, db, config, random_obstacle_policy(4), 300, seed=2)
    assert 0.02 < np.mean(obs[:, :512] != 0) < 0.9  # the maps hold obstacles, and zeros to skip
    dense = np.random.default_rng(0).normal(0, 2, obs.shape).astype(np.float32)
    # The paper's sizes, and layers wider than one pass of the kernels (64 outputs) and not whole lanes.
    for policy in (random_obstacle_policy(4), random_obstacle_policy(4, channels=(20, 70), map_features=100,
                                                                     head=(140, 36))):
        path = tmp_path / "cnn.mmrl"
        write_controller(path, db, policy, "obstacles", config)
        c = _core.RuntimeController.load(str(path))
        for batch in (obs, dense):
            ours = np.stack([c.act(o) for o in batch])
            # The reference: the same network in float64 (torch's float32 is itself 2e-6 / 8e-6 off it).
            with torch.no_grad():
                normalized = policy.obs_normalizer(torch.as_tensor(batch)).double()
                ref = copy.deepcopy(policy.model).double().actor_mean(normalized).numpy()
            # measured 2.5e-6 (the task's observations) and 5.9e-6 (dense)
            assert np.max(np.abs(ours - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-5
            assert np.ptp(ref, axis=0).min() > 1e-3


def test_obstacle_runtime_equals_python_full_path(tmp_path):
    """The obstacles task: the engine hands the runtime the env's obstacles before each
    decision; the sensor maps (current and previous), the CNN's actions and the decisions agree
    with the Python full path until the episode ends (a collision resets the env's map history,
    which an engine does not do)."""
    from mmrl.tasks.obstacles import ObstaclesConfig

    task, db = mmrl.get_task("obstacles"), mmrl.default_database()
    config = ObstaclesConfig(transition_cost=5.0, num_obstacles=40)
    path = tmp_path / "obstacles.mmrl"
    write_controller(path, db, random_obstacle_policy(3), "obstacles", config)
    c = _core.RuntimeController.load(str(path))
    assert c.obs_dim == 529 and c.task_name == "obstacles"
    compared = transitions = seen = 0
    for seed in range(20):
        fp = FullPath(task, db, config=config, seed=seed, record=False)
        ch = _core.RuntimeCharacter(c, *fp.character.root, fp.character.frame)
        ch.set_target(*fp.target)
        for _ in range(300):
            o = fp.env.obstacles(0)
            ch.set_obstacles(*(np.ascontiguousarray(o[k], np.float32) for k in ("centres", "half_sizes", "angles")))
            np.testing.assert_array_equal(ch.observe(), fp.obs)
            seen += fp.obs[:512].any()
            step = fp.step(c.act(fp.obs))
            for k in range(step["res"].frames.size):
                ch.advance_frame()
                assert ch.frame == step["res"].frames[k]
                np.testing.assert_allclose(ch.global_positions(), step["res"].positions[k], atol=1e-4)
            assert ch.last_decision()["match"] == step["res"].match
            compared += 1
            transitions += step["res"].transition
            if step["done"]:
                break
    # Not vacuous: many decisions, with obstacles in the sensor maps, and clip changes.
    assert compared >= 150 and seen >= 100 and transitions >= 20, (compared, seen, transitions)


@pytest.fixture(scope="module")
def stick_file(tmp_path_factory):
    """A plane controller (a random policy: a stick never runs it) on the synthetic database."""
    path = tmp_path_factory.mktemp("stick") / "plane.mmrl"
    write_controller(path, mmrl.default_database(), random_plane_policy(2), "plane", PlaneConfig(transition_cost=5.0))
    return path


def heading_and_speed(phase_roots, fps=30.0, frames=6):
    """Per phase: (unit world displacement, mean speed in m/s over its decisions)."""
    out = []
    for (a, b), n in phase_roots:
        move = b[:2] - a[:2]
        out.append((move / np.linalg.norm(move), np.linalg.norm(move) / (n * frames / fps)))
    return out


def test_a_stick_decides_as_the_joystick_toward_a_far_target(stick_file):
    """The reference: Python's full path whose target is reset before every decision to the
    character's root + 1000 m along the stick, acting with JoystickPolicy at the stick's speed.
    Two sticks (walking and running speeds, one direction unnormalized), then set_target hands
    the character back to the policy, then a stick again: the same matched frames, shown frames
    and roots as the reference, decision for decision; the stick's action equals the joystick's
    within float rounding; and the character goes roughly where the stick points."""
    from mmrl.rl.policies import database_speeds

    db = read_controller(stick_file).db
    walk, run = database_speeds(db)
    phases = [("stick", (1.0, 0.0), walk, 250), ("stick", (0.6, -4.0), run, 250), ("target", (3.0, 4.0), 150),
              ("stick", (-1.0, 1.0), 1.5, 150)]
    out = drive_stick(stick_file, mmrl.get_task("plane"), db, PlaneConfig(transition_cost=5.0), phases)
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5 and out["pose_error"] <= 1e-4, out
    assert out["action_error"] <= 1e-5, out["action_error"]
    np.testing.assert_array_equal(out["sticks"], [True] * 500 + [False] * 150 + [True] * 150)
    assert out["transitions"] >= 40  # not vacuous: the sticks turn the character and change clips
    sticks = [(phases[k][1], phases[k][2], phases[k][3]) for k in (0, 1, 3)]
    walked = heading_and_speed([(out["phase_roots"][k], phases[k][-1]) for k in (0, 1, 3)])
    for (direction, speed, _), (heading, mean_speed) in zip(sticks, walked):
        # Within 20 degrees and half the speed: the synthetic clips turn and keep playing under the
        # transition cost (measured: 6 degrees off, 1.25 m/s for a walk of 1.26 m/s; the reference's own).
        assert heading @ (np.array(direction) / np.hypot(*direction)) > np.cos(np.radians(20)), (direction, heading)
        assert 0.5 * speed < mean_speed < 1.5 * speed, (speed, mean_speed)


def test_a_stick_keeps_to_a_request(stick_file):
    db = read_controller(stick_file).db
    out = drive_stick(stick_file, mmrl.get_task("plane"), db, PlaneConfig(transition_cost=5.0),
                      [("stick", (0.0, 1.0), 2.5, 200)], seed=1, request="gait=run")
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    run = db.clip_tags[:, db.tag_names.index("gait=run")]
    assert run[db.frame_clip[out["rt_matches"]]].all()


def test_a_stick_goes_through_the_obstacle_tasks_path_filter(tmp_path):
    """Moving obstacles and the collision-aware search: the stick's decisions equal the
    joystick's full path's with the filter; a file without the filter decides otherwise."""
    task, db = mmrl.get_task("obstacles"), mmrl.default_database()
    config = task.default_config().replace(num_obstacles=60, obstacle_max_speed=1.0, path_filter=True,
                                           path_cost=50.0, path_candidates=32, transition_cost=5.0)
    with_filter, without = tmp_path / "with.mmrl", tmp_path / "without.mmrl"
    write_controller(with_filter, db, random_obstacle_policy(3), "obstacles", config)
    write_controller(without, db, random_obstacle_policy(3), "obstacles", config.replace(path_filter=False))
    compared = differ = 0
    for seed in range(8):
        phase = [("stick", [(1.0, 0.5), (-0.2, 1.0), (0.0, -1.0)][seed % 3], [1.2, 2.5][seed % 2], 200)]
        out = drive_stick(with_filter, task, db, config, phase, seed=seed, stop_at_done=True)
        np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
        assert out["action_error"] <= 1e-5
        compared += out["rt_matches"].size
        plain = drive_stick(without, task, db, config, phase, seed=seed, stop_at_done=True)
        differ += not np.array_equal(plain["rt_matches"], plain["py_matches"])
    assert compared >= 200 and differ >= 3, (compared, differ)


def test_a_stick_on_a_compressed_controller(tmp_path):
    """A compressed file: the stick's action goes to the projector. Its decisions are continuous,
    so the float rounding between the stick's action and the joystick's (within 1e-5) would grow:
    the Python compressed full path plays the runtime's own stick action, and both must agree."""
    from mmrl.compress import CompressConfig, train_compressed
    from mmrl.compress.model import CompressedModel
    from mmrl.export.compressed_export import write_compressed_controller
    from mmrl.export.runtime_file import read_sections

    torch.set_num_threads(1)
    db, task, config = mmrl.default_database(), mmrl.get_task("plane"), PlaneConfig(transition_cost=5.0)
    cfg = CompressConfig(iterations=100, hidden=(32, 32), latent=8, checkpoint_every=1000, batch=64,
                         stepper_iterations=50, projector_iterations=50, stepper_hidden=(32, 32),
                         projector_hidden=(32, 32), stepper_window=8)
    train_compressed(db, tmp_path / "c.pt", cfg, progress=False)
    compressed = CompressedModel(tmp_path / "c.pt", db)
    path = tmp_path / "c.mmrl"
    write_compressed_controller(path, db, random_plane_policy(2), task, config, compressed)
    source = read_sections(path)["lmm.start_sources"]
    out = drive_stick(path, task, db, config, [("stick", (0.6, -0.8), 1.3, 100), ("stick", (-1.0, 0.0), 2.0, 100)],
                      compressed=compressed, start=(int(source[0]), 0), runtime_actions=True)
    assert out["root_error"] == 0.0 and out["pose_error"] <= 1e-4, out
    assert out["action_error"] <= 1e-5 and out["transitions"] >= 5, out  # measured 4e-7 and 16
    assert (out["rt_matches"] == -1).all()


def test_the_stick_refuses_bad_values_and_set_target_ends_it(stick_file):
    c = _core.RuntimeController.load(str(stick_file))
    ch = _core.RuntimeCharacter(c, 1.0, 2.0, 0.5)
    assert not ch.stick
    with pytest.raises(ValueError, match="no stick"):
        ch.stick_action()
    ch.set_stick(0.0, 2.0, 1.2)
    before = ch.stick_action()
    nan, inf = float("nan"), float("inf")
    for x, z in [(0.0, 0.0), (nan, 1.0), (1.0, inf), (-inf, 0.0)]:
        with pytest.raises(ValueError, match=r"stick: the direction \(x, z\) must be finite and not zero"):
            ch.set_stick(x, z, 1.0)
    for speed in (0.0, -1.0, nan, inf):
        with pytest.raises(ValueError, match="stick: the speed must be finite and > 0"):
            ch.set_stick(1.0, 0.0, speed)
    np.testing.assert_array_equal(ch.stick_action(), before)  # refused: the character is unchanged
    # Any length: (0, 2) is (0, 1); and the heading now turns the stick into the character frame.
    ch.set_stick(0.0, 1e-30, 1.2)
    np.testing.assert_array_equal(ch.stick_action(), before)
    ch.update(0.2)
    assert ch.last_decision()["stick"]
    ch.set_target(5.0, 5.0)
    assert not ch.stick
    ch.update(0.2)
    assert not ch.last_decision()["stick"] and ch.last_decision()["count"] == 2
