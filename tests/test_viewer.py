"""The browser viewer's logic without a browser: the live loop (mmrl play), playbacks
(mmrl view) of a second skeleton and of a database, the HTML export, and bad input.

The live loop runs with the joystick policy (a known reference: a straight line to the
target at walking speed), so no training is needed."""
import importlib.util
import json
import socket

import numpy as np
import pytest

import mmrl
from mmrl import _core, synth
from mmrl.metrics import rate_per_second
from mmrl.rl.policies import JoystickPolicy
from mmrl.viewer.live import LiveSession

TRACE_KEYS = {"t", "root", "target", "frame", "transition"}


@pytest.fixture(scope="module")
def db():
    return mmrl.motion.sources.database_from_spec(mmrl.motion.sources.data_spec())


def session(db, task="plane", **kw):
    t = mmrl.get_task(task)
    return LiveSession(t, db, JoystickPolicy.preset(db, "joystick"), config=t.default_config(), **kw)


def distance(s, target):
    x, z, _ = s.root
    return float(np.hypot(target[0] - x, target[1] - z))


def test_target_acts_at_the_next_decision_and_the_root_gets_there(db, tmp_path):
    trace = tmp_path / "trace.jsonl"
    s = session(db, trace=str(trace))
    for _ in range(9):  # decisions at frames 0 and 6; frame 9 is mid-step
        s.step()
    target = np.array(s.root[:2]) + [3.0, -2.0]
    s.set_target(*target)
    assert np.allclose(s.target, s.run.target)  # not yet applied: pending until the next decision
    assert not np.allclose(s.target, target)
    before = distance(s, target)
    for _ in range(3):  # frames 9, 10, 11; the next frame decides
        s.step()
    assert s.decisions == 2
    s.step()
    assert s.decisions == 3 and np.allclose(s.target, target)
    # That decision already asks for the new target: its 1 s-ahead point is nearer to it by
    # about the walking distance of one second (joystick: a straight line toward the target).
    speed = JoystickPolicy.preset(db, "joystick").speed
    ahead = s.shown["query_points"][2]
    assert np.hypot(*(target - ahead)) < before - 0.5 * speed
    dists = []
    for _ in range(30 * 5):
        s.step()
        dists.append(distance(s, target))
    assert dists[-1] < 0.6 < before - 2.0  # reached
    s.close()
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    assert [set(line) for line in lines] == [TRACE_KEYS] * len(lines)
    applied = [np.allclose(line["target"], target, atol=1e-4) for line in lines]
    assert applied[:2] == [False] * 2 and all(applied[2:])  # from the first decision after the click on
    np.testing.assert_allclose([line["t"] for line in lines], np.arange(len(lines)) * 0.2, atol=1e-6)
    assert all(isinstance(line["transition"], bool) and 0 <= line["frame"] < db.num_frames for line in lines)
    assert all(len(line["root"]) == 3 and len(line["target"]) == 2 for line in lines)


def test_trace_root_is_the_root_at_each_decision(db, tmp_path):
    trace = tmp_path / "t.jsonl"
    s = session(db, trace=str(trace))
    roots = []
    for i in range(6 * 8):
        if i % 6 == 0:
            roots.append(s.root)
        s.step()
    s.close()
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    np.testing.assert_allclose([line["root"] for line in lines], roots, atol=1e-4)


def test_live_quality_counts_the_window_transitions(db, tmp_path):
    trace = tmp_path / "t.jsonl"
    s = session(db, trace=str(trace), window_steps=10)
    s.set_target(4.0, 4.0)
    for _ in range(6 * 25):
        s.step()
    s.close()
    lines = [json.loads(line) for line in trace.read_text().splitlines()]
    transitions = sum(line["transition"] for line in lines[-10:])
    q = s.quality()
    assert q["transitions_per_s"] == pytest.approx(rate_per_second(transitions, 60, db.fps))
    assert q["matched_cost_mean"] == pytest.approx(np.mean([r.cost for r in list(s.window)[1:]]), rel=1e-6)
    assert q["seconds"] == pytest.approx(2.0)


def test_ik_toggle_shows_the_animated_ankles(db):
    s = session(db, window_steps=10)
    s.set_options(ik=False)
    for _ in range(6 * 12):
        s.step()
    q = s.quality()  # IK off: the shown ankles are the animated ones, so both sliding numbers agree
    assert q["foot_sliding_cm_per_s"] == pytest.approx(q["foot_sliding_ik_off_cm_per_s"], rel=1e-6)
    s.set_options(ik=True, inertialization=False)
    for _ in range(6 * 12):
        s.step()
    q = s.quality()
    assert q["foot_sliding_cm_per_s"] < q["foot_sliding_ik_off_cm_per_s"]


def test_policy_switch_follows_the_same_target(db):
    s = session(db)
    s.policies["trained"] = None  # never asked once the switch has applied
    calls = []

    joystick = JoystickPolicy.preset(db, "joystick")

    class Spy:
        def bind_layout(self, layout):
            joystick.bind_layout(layout)

        def act(self, obs, deterministic=True):
            calls.append(obs.copy())
            return joystick.act(obs)

    s.policies["joystick"] = Spy()
    s.set_policy("joystick")
    s.set_target(2.0, 2.0)
    x, z, yaw = s.root
    s.step()
    assert s.policy_name == "joystick" and len(calls) == 1
    # It sees the clicked target in the character frame of the decision's root.
    dx, dz = 2.0 - x, 2.0 - z
    c, sn = np.cos(yaw), np.sin(yaw)
    np.testing.assert_allclose(calls[0][0, -2:], [c * dx - sn * dz, sn * dx + c * dz], atol=1e-4)
    with pytest.raises(ValueError, match="policy must be one of"):
        s.set_policy("nope")


def test_obstacles_drag_and_pause(db):
    s = session(db, task="obstacles", seed=3)
    s.step()
    s.pause_obstacles(True)
    for _ in range(6):
        s.step()
    frozen = s.obstacle_centres()
    for _ in range(12):
        s.step()
    np.testing.assert_array_equal(s.obstacle_centres(), frozen)
    far = int(np.argmax(np.hypot(*(frozen - np.array(s.root[:2])).T)))
    s.move_obstacle(far, *(0.9 * frozen[far]))
    s.move_obstacle(0, 1e3, -1e3)  # dragged out of the obstacle square: held at its corner
    for _ in range(6):
        s.step()
    np.testing.assert_allclose(s.obstacle_centres()[far], 0.9 * frozen[far], atol=1e-5)
    half = s.config.obstacle_square_half
    np.testing.assert_allclose(s.obstacle_centres()[0], [half, -half], atol=1e-5)
    s.pause_obstacles(False)
    for _ in range(12):
        s.step()
    moving = np.hypot(*s.run.env.obstacles(0)["velocities"].T) > 0
    assert moving.any()
    assert s.shown["obstacles"].shape == (len(frozen), 4, 2) and s.shown["sensors"]["map"].shape == (16, 16)


def test_play_shows_the_continuation_s_path_and_where_it_hits(db):
    """mmrl play draws, per decision, the path the playing clip would take if it continued (its
    frame's path samples through the root) with the collision-aware search's hits in red."""
    s = session(db, task="obstacles", seed=5)
    seen = red = 0
    reach = []
    for _ in range(240):
        env = s.run.env
        deciding = s.k >= s.F
        if deciding:
            state = env.env_state(0)
            frame = int(state["frame"])
            want_hit = int(env.path_hits(0, np.array([frame]))[0]) if db.valid_mask[frame] else None
        s.step()
        if not deciding:
            continue
        path = s.shown["continuation_path"]
        if want_hit is None:
            assert path is None
            continue
        seen += 1
        c, sn = np.cos(state["yaw"]), np.sin(state["yaw"])
        local = db.path_samples[frame]
        world = np.column_stack([state["x"] + c * local[:, 0] + sn * local[:, 1],
                                 state["z"] - sn * local[:, 0] + c * local[:, 1]])
        np.testing.assert_allclose(path["points"], world, atol=1e-4)
        reach.append(np.hypot(*(world[-1] - [state["x"], state["z"]])))  # 1 s ahead: the clip's speed
        frames = np.asarray(_core.PATH_SAMPLE_FRAMES)
        np.testing.assert_array_equal(path["inside"], frames >= want_hit if want_hit else np.zeros(9, bool))
        red += bool(path["inside"].any())
    assert seen >= 20 and red >= 1 and np.mean(reach) > 0.5, (seen, red, np.mean(reach))


def test_ground_hit():
    from mmrl.viewer.scene import ground_hit

    assert ground_hit((1.0, 2.0, 3.0), (0.0, -1.0, 1.0)) == pytest.approx((1.0, 5.0))
    assert ground_hit((0.0, 2.0, 0.0), (0.0, 0.5, 1.0)) is None  # above the horizon
    assert ground_hit((0.0, -1.0, 0.0), (0.0, -1.0, 0.0)) is None  # below the ground, looking down


# ----------------------------------------------------------------------------- playbacks
@pytest.fixture(scope="module")
def other_bvh(tmp_path_factory):
    """A synthetic walk written on another skeleton (Mixamo names, other channel orders, meters)."""
    from test_import_axes_fps import other_skeleton, read_clip

    out = tmp_path_factory.mktemp("bvh")
    synth.write_clip(out / "walk.bvh", speed=1.4, turn_rate=0.3, seconds=3.0, seed=2)
    path = out / "mixamo.bvh"
    path.write_text(other_skeleton(read_clip((out / "walk.bvh").read_text())).text())
    return path


def test_bvh_playback_on_another_skeleton(other_bvh):
    from mmrl.viz.render import joint_sides, skeleton_bones
    from mmrl.viewer.clips import load_playback

    pb = load_playback(str(other_bvh))
    motion = mmrl.load_bvh(other_bvh)
    np.testing.assert_allclose(pb.recording["positions"], motion.global_positions(), atol=1e-6)
    assert pb.clips == [("mixamo.bvh", 0, motion.num_frames)]
    assert len(skeleton_bones(pb.parents)) == len(pb.parents) - 1
    sides = dict(zip(pb.joint_names, joint_sides(pb.joint_names)))
    assert sides["mixamorig:LeftUpLeg"] == 1 and sides["mixamorig:RightFoot"] == 2 and sides["mixamorig:Hips"] == 0
    assert pb.frame(5)["positions"].shape == (len(pb.parents), 3)


def test_database_playback_clips(db, tmp_path):
    from mmrl.viewer.clips import load_playback

    path = tmp_path / "db.npz"
    db.save(path)
    pb = load_playback(str(path))
    ranges = np.asarray(db.clip_ranges).reshape(-1, 2)
    assert [(a, b) for _, a, b in pb.clips] == [tuple(map(int, r)) for r in ranges]
    f = int(ranges[-1, 0]) + 3
    np.testing.assert_allclose(pb.frame(f)["positions"],
                               _core.database_global_positions(db._db, np.array([f], np.int64))[0], atol=1e-6)
    np.testing.assert_array_equal(pb.frame(f)["contacts"], db.contacts[f])


# ----------------------------------------------------------------------------- command line
def one_line_error(capsys, args, *fragments):
    """``mmrl ARGS`` (in this process) fails with one ``mmrl: error:`` line naming ``fragments``."""
    from mmrl.cli import main

    assert main([str(a) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mmrl: error:"), err
    for f in fragments:
        assert f in err[0], err[0]


def test_bad_input_is_one_line(tmp_path, capsys):
    one_line_error(capsys, ["view", tmp_path / "missing", "--no-browser"], "missing")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{not json")
    one_line_error(capsys, ["view", tmp_path / "run", "--no-browser"], "config.json", "not valid JSON")
    one_line_error(capsys, ["play", tmp_path / "run", "--no-browser"], "config.json")
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 zero\n}\n")
    one_line_error(capsys, ["view", bad, "--no-browser"], "bad.bvh:4:")
    one_line_error(capsys, ["render", "--length", "1"], "--html")
    one_line_error(capsys, ["render", "--length", "1", "--html", tmp_path / "x.txt"], "x.txt", ".html")
    one_line_error(capsys, ["view", bad, "--port", "70000"], "--port")


needs_viser = pytest.mark.skipif(importlib.util.find_spec("viser") is None,
                                 reason="the viewer extra is not installed: pip install 'mmrl[viewer]'")


@needs_viser
def test_busy_port_moves_to_the_next_free_one():
    from mmrl.viewer.scene import Scene

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        scene = Scene("127.0.0.1", port)
        try:
            assert scene.port != port and scene.port > port
            assert scene.url == f"http://127.0.0.1:{scene.port}/"
        finally:
            scene.close()


@needs_viser
def test_host_beyond_this_machine_warns():
    from mmrl.viewer.scene import check_host

    with pytest.warns(UserWarning, match="anyone who can reach"):
        check_host("0.0.0.0")
    assert check_host("127.0.0.1") == "127.0.0.1"
    with pytest.raises(mmrl.errors.InputError, match="--host"):
        check_host("not a host")


@needs_viser
def test_html_export_of_20_seconds(tmp_path):
    from mmrl.cli import main

    out = tmp_path / "plane.html"
    assert main(["render", "--policy", "joystick", "--length", "20", "--html", str(out)]) == 0
    page = out.read_text()
    assert out.stat().st_size < 10e6
    assert "window.__VISER_EMBED_DATA__=" in page
    from mmrl.viewer.export import check_offline

    check_offline(page)  # no script, style or font from the network
    with pytest.raises(RuntimeError, match="network"):
        check_offline('<script src="https://cdn.example/x.js"></script>')


def test_limbs_are_closed_capsules_turned_onto_their_bones():
    """The body's capsules (docs/styles.md: the body shows the style): a closed surface (every edge
    in two faces) of the asked length and radius, and rotations taking +Z onto each bone."""
    from mmrl.viewer.draw import capsule_mesh, limb_radii, rotation_from_z

    v, f = capsule_mesh(0.4, 0.05)
    edges = {}
    for a, b, c in f:
        for e in ((a, b), (b, c), (c, a)):
            key = tuple(sorted(int(x) for x in e))
            edges[key] = edges.get(key, 0) + 1
    assert set(edges.values()) == {2}
    np.testing.assert_allclose([v[:, 2].min(), v[:, 2].max()], [-0.05, 0.45], atol=1e-6)
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]).max(), 0.05, atol=1e-6)
    d = np.array([[0, 0, 1], [1, 0, 0], [0, -1, 0], [0, 0, -1], [0.3, 0.4, -0.5]], np.float64)
    q = rotation_from_z(d)
    w, x, y, z = q.T
    # The rotated +Z axis: the third column of each rotation matrix.
    rz = np.column_stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
    np.testing.assert_allclose(rz, d / np.linalg.norm(d, axis=1, keepdims=True), atol=1e-9)
    r = limb_radii(np.array([0.4, 0.1, 0.1]), np.array([False, False, True]), 0.2)
    np.testing.assert_allclose(r, [0.06, 0.025, 0.2 / 3])


def test_the_timing_report_measures_the_characters_playback(db):
    """mmrl play's "matching, inertialization, IK" line times what the full path calls (it read
    0.00 ms while it wrapped a method the full path never calls): one sample per decision, each
    inside the decision's env + controller time."""
    s = session(db)
    for _ in range(6 * 5):
        s.step()
    controller, whole = s.timing["controller"], s.timing["env_and_controller"]
    assert len(controller) == len(whole) == 5
    assert all(0 < c <= w for c, w in zip(controller, whole))


def test_recorded_match_features_are_the_played_frames_own(db):
    """Every motion source records the chosen trajectory (``match_features``); the database's is
    the trajectory of the frame before the next one shown (the decision plays match + 1 ...)."""
    from mmrl.motion.database import POSE_DIM, TRAJECTORY_DIM
    from mmrl.rollout import follow
    from mmrl.viewer.clips import add_matched_queries

    task = mmrl.get_task("plane")
    rec = follow(task, db, JoystickPolicy.preset(db, "joystick"), seconds=4.0, seed=3, config=task.default_config())
    qf, frames = np.asarray(rec["query_frames"]), np.asarray(rec["frames"])
    inside = qf + 1 < len(frames)
    played = frames[qf[inside] + 1] - 1
    want = np.asarray(db.normalized_features, np.float32)[played, POSE_DIM:POSE_DIM + TRAJECTORY_DIM]
    np.testing.assert_array_equal(np.asarray(rec["match_features"])[inside], want)
    assert inside.sum() >= 15
    add_matched_queries(db, rec)
    assert rec["match_points"].shape == (len(qf), 3, 2)
