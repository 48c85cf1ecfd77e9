"""The C++ runtime (mmrl_runtime, cpp/include/mmrl/runtime.hpp) against Python's full path.

Given the same controller file, start and targets, the runtime and mmrl.rollout.FullPath (the
loop ``mmrl play`` runs) make the same decisions, show the same frames and roots, and the
same poses. The runtime's policy (policy_net.hpp) matches torch's within float rounding.
"""
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
from runtime_helpers import drive_both


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


def random_plane_policy(seed: int) -> Policy:
    torch.manual_seed(seed)
    model = PlaneActorCritic(17, 12)
    with torch.no_grad():
        model.actor[-1].weight.normal_(0, 0.5)
    norm = ObsNormalizer(17, True, None, 10.0, torch.device("cpu"))
    norm.rms.var = np.full(17, 4.0)
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


def random_obstacle_policy(seed: int, layout=None) -> Policy:
    """A CNN policy with random weights for the obstacles task's observation (``layout``: an
    env's, e.g. with observe_continuation; default the paper's 529 floats)."""
    from mmrl.rl.networks import OBSTACLE_DEFAULT_LAYOUT, ObstacleActorCritic

    torch.manual_seed(seed)
    layout = tuple(layout or OBSTACLE_DEFAULT_LAYOUT)
    model = ObstacleActorCritic(12, layout=layout)
    with torch.no_grad():
        model.actor.head[-1].weight.normal_(0, 0.3)
    norm = ObsNormalizer(model.obs_dim, True, ObstacleActorCritic.map_range(layout), 10.0, torch.device("cpu"))
    norm.refresh()
    return Policy(model, norm, torch.device("cpu"))


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
        ch = _core.RuntimeCharacter(c, *fp.ctrl.root, fp.ctrl.frame)
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
