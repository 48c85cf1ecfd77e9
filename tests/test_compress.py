"""Learned motion matching, first part (issue 27): the pose a compressed controller reproduces, the
compressor and decompressor, and their file. On the package's skeleton and on a second one
(Mixamo names, other channel orders).

- The pose rows and their forward kinematics give back the database's own joint positions
  (the C++ forward kinematics, taken to each frame's character frame).
- A short training reproduces held-back clips' poses within a stated tolerance.
- Training is reproducible with a seed, and a resumed run equals one that never stopped.
- A corrupt, foreign or mismatched file is refused with the file's name and the reason."""
import numpy as np
import pytest
import torch

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.compress import (CompressConfig, CompressData, CompressedFileError, joint_errors_cm, load_compressed,
                           networks_from, pose_targets, reconstruct, train_compressed)
from mmrl.compress.train import _positions
from test_import_axes_fps import other_skeleton_database

#: Held-back clips' mean joint position error after the short test training (cm). The bench
#: (docs/compressed.md) reports what a full training reaches.
HOLDOUT_TOLERANCE_CM = 3.0


@pytest.fixture(scope="module", params=["synthetic", "mixamo"])
def db(request, tmp_path_factory):
    if request.param == "synthetic":
        return mmrl.default_database()
    return other_skeleton_database(tmp_path_factory.mktemp("mixamo-compress"),
                                   clips=((1.4, 0.3), (1.2, -0.5), (3.0, 0.2), (0.8, 0.0), (2.2, -0.3)))


def test_pose_rows_give_back_the_database_poses(db):
    frames = np.arange(0, db.num_frames, 37, dtype=np.int64)
    world = _core.database_global_positions(db._db, frames).astype(np.float64)
    root, yaw = np.asarray(db.root_positions)[frames], np.asarray(db.root_yaws)[frames]
    c, s = np.cos(yaw), np.sin(yaw)
    d = world - root[:, None, :]
    # World -> character frame: the inverse of the yaw rotation about +Y.
    local = np.stack([c[:, None] * d[..., 0] - s[:, None] * d[..., 2], d[..., 1],
                      s[:, None] * d[..., 0] + c[:, None] * d[..., 2]], -1)
    y = pose_targets(db)
    assert y.shape == (db.num_frames, 9 * db.num_joints + 5)
    fk = _positions(torch.as_tensor(y[frames], dtype=torch.float64), list(db.parents), db.num_joints).numpy()
    np.testing.assert_allclose(fk, local, atol=2e-4)
    np.testing.assert_array_equal(y[:, -5:-2], np.asarray(db.root_deltas, np.float32))
    np.testing.assert_array_equal(y[:, -2:], np.asarray(db.contacts, np.float32))


#: Small networks and stages for the tests (the defaults train for an hour).
QUICK = dict(stepper_iterations=150, projector_iterations=150, stepper_hidden=(64, 64), projector_hidden=(64, 64),
             stepper_window=8)


def test_a_short_training_reproduces_held_back_clips(db, tmp_path):
    torch.set_num_threads(1)
    cfg = CompressConfig(iterations=600, hidden=(128, 128), latent=16, holdout_every=4, checkpoint_every=300, **QUICK)
    out = tmp_path / "c.pt"
    res = train_compressed(db, out, cfg, progress=False)
    assert res["stage"] == "done" and (tmp_path / "c-metrics" / "metrics.csv").is_file()
    assert res["holdout_joint_error_cm"] < HOLDOUT_TOLERANCE_CM
    state = load_compressed(out, db)
    assert (state["decompressor_iterations"], state["stepper_iterations"], state["projector_iterations"]) == \
        (600, 150, 150)
    data = CompressData.from_database(db, cfg.holdout_every)
    comp, decomp, _ = networks_from(state, data.y.shape[1])
    frames = data.holdout_frames
    err = joint_errors_cm(data, frames, reconstruct(comp, decomp, data, frames))
    assert err.mean() < HOLDOUT_TOLERANCE_CM
    # Against a reference that knows nothing: the mean pose of the training frames.
    mean = np.repeat(data.y_mean[None], frames.size, 0)
    assert err.mean() < 0.25 * joint_errors_cm(data, frames, mean).mean()


def test_seeded_and_resumed_runs_agree(tmp_path):
    """A run stopped inside the stepper stage (a checkpoint) and resumed ends bit for bit where one
    that never stopped does: networks, Adam and the sampler's RNG are all in the file."""
    db = mmrl.default_database()
    cfg = CompressConfig(iterations=200, hidden=(32, 32), latent=8, checkpoint_every=50, batch=64,
                         **{**QUICK, "stepper_iterations": 100, "projector_iterations": 100})
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    train_compressed(db, a, cfg, progress=False)
    import mmrl.compress.train as train_mod

    calls = {"n": 0}
    real = train_mod.stepper_losses

    def stop_after_checkpoint(*args, **kwargs):  # a kill right after the stepper's first checkpoint
        calls["n"] += 1
        if calls["n"] > 50:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    train_mod.stepper_losses = stop_after_checkpoint
    try:
        with pytest.raises(KeyboardInterrupt):
            train_compressed(db, b, cfg, progress=False)
    finally:
        train_mod.stepper_losses = real
    mid = load_compressed(b)
    assert (mid["stage"], mid["iteration"]) == ("stepper", 50)
    train_compressed(db, b, cfg, resume=True, progress=False)
    sa, sb = load_compressed(a), load_compressed(b)
    assert sa["stage"] == sb["stage"] == "done"
    for key in ("compressor", "decompressor", "stepper", "projector"):
        for name, tensor in sa[key].items():
            torch.testing.assert_close(tensor, sb[key][name], rtol=0, atol=0, msg=f"{key}.{name}")


def test_bad_files_are_refused_with_the_reason(tmp_path, capsys):
    db = mmrl.default_database()
    out = tmp_path / "c.pt"
    assert main(["compress", "-o", str(out), "--iterations", "20", "--set", "hidden=16,16", "--no-progress",
                 "--set", "stepper_iterations=10", "--set", "projector_iterations=10", "--set", "stepper_hidden=16",
                 "--set", "projector_hidden=16"]) == 0
    assert "held-back clips" in capsys.readouterr().out
    assert main(["compress", "-o", str(out), "--iterations", "20"]) == 2  # it exists: --resume or another -o
    assert "--resume" in capsys.readouterr().err
    load_compressed(out, db)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(out.read_bytes()[:100])
    with pytest.raises(CompressedFileError, match="bad.pt: corrupt"):
        load_compressed(bad)
    (tmp_path / "other").mkdir()
    other = other_skeleton_database(tmp_path / "other")
    with pytest.raises(CompressedFileError, match="made for another database"):
        load_compressed(out, other)
    foreign = tmp_path / "foreign.pt"
    torch.save({"format": "something else"}, foreign)
    with pytest.raises(CompressedFileError, match="not an mmrl compressed-controller file"):
        load_compressed(foreign)

    class Evil:
        def __reduce__(self):
            return (print, ("code ran",))

    evil = tmp_path / "evil.pt"
    torch.save({"format": "mmrl-compressed", "x": Evil()}, evil)
    with pytest.raises(CompressedFileError, match="refused"):
        load_compressed(evil)
    assert "code ran" not in capsys.readouterr().out
    assert main(["compress", str(bad), "-o", str(tmp_path / "x.pt")]) == 2  # not a run or a database


# ----------------------------------------------------------------------------- playing it
def small_compressed(db, out):
    """A small compressed controller of db, trained to the end into out (returned)."""
    torch.set_num_threads(1)
    cfg = CompressConfig(iterations=300, hidden=(64, 64), latent=8, checkpoint_every=1000, **QUICK)
    train_compressed(db, out, cfg, progress=False)
    return out


@pytest.fixture(scope="module")
def trained(db, tmp_path_factory):
    """A small compressed controller of each skeleton, trained to the end."""
    return small_compressed(db, tmp_path_factory.mktemp("compressed") / "c.pt")


def test_the_core_networks_equal_torch(db, trained):
    from mmrl.compress.model import CompressedModel

    import copy

    cc = CompressedModel(trained, db)
    # The core runs float16 weights (compressed.hpp): the reference is torch over the same
    # weights rounded to float16 (IEEE, nearest even), computed in float32.
    nets = {n: copy.deepcopy(cc.networks[n]) for n in ("decompressor", "stepper", "projector")}
    for net in nets.values():
        for m in net:
            if isinstance(m, torch.nn.Linear):
                m.weight.data = m.weight.data.half().float()
    rng = np.random.default_rng(3)
    s = rng.standard_normal((64, cc.core.state_dim)).astype(np.float32)
    q = rng.standard_normal((64, 27)).astype(np.float32)
    with torch.no_grad():
        z = torch.as_tensor(s[:, 27:]) * torch.as_tensor(cc.z_std) + torch.as_tensor(cc.z_mean)
        pose = nets["decompressor"](torch.cat([torch.as_tensor(s[:, :27]), z], 1)) * torch.as_tensor(cc.y_std) + \
            torch.as_tensor(cc.y_mean)
        step = torch.as_tensor(s) + nets["stepper"](torch.as_tensor(s))
        proj = nets["projector"](torch.as_tensor(q))
    free = np.ones(cc.core.pose_dim, bool)
    J = db.num_joints
    for j in np.flatnonzero(cc.fixed_joints):
        free[6 * J + 3 * j:6 * J + 3 * j + 3] = False
    np.testing.assert_allclose(cc.decode(s)[:, free], pose.numpy()[:, free], atol=2e-5, rtol=1e-5)
    np.testing.assert_allclose(cc.core.step(s), step.numpy(), atol=2e-5, rtol=1e-5)
    np.testing.assert_allclose(cc.core.project(q), proj.numpy(), atol=2e-5, rtol=1e-5)
    assert cc.core.num_frame_states == db.num_frames
    J = db.num_joints
    linear = [m for n in ("decompressor", "stepper", "projector") for m in nets[n] if isinstance(m, torch.nn.Linear)]
    packed = sum(2 * 8 * -(-m.out_features // 8) * m.in_features + 4 * m.out_features for m in linear)
    assert cc.memory_bytes == packed + 4 * (2 * cc.core.pose_dim + 2 * 8 + 3 * J) + J
    # Bones keep their lengths: a joint whose translation never changes in the database decodes to it.
    tr = np.asarray(db.bone_translations)
    fixed = np.abs(tr - tr[:1]).max(axis=(0, 2)) <= 1e-6
    assert fixed.sum() >= J // 2
    decoded = cc.decode(s)[:, 6 * J:9 * J].reshape(-1, J, 3)
    np.testing.assert_array_equal(decoded[:, fixed], np.broadcast_to(tr[0, fixed], decoded[:, fixed].shape))


def test_both_kernels_give_the_same_bits(db, trained, tmp_path):
    """The F16C kernel and the widening one (MMRL_NO_F16C, what a CPU without F16C runs) decode,
    step and project to the same bits."""
    import os
    import subprocess
    import sys

    from mmrl.compress.model import CompressedModel

    cc = CompressedModel(trained, db)
    s = np.random.default_rng(4).standard_normal((16, cc.core.state_dim)).astype(np.float32)
    np.save(tmp_path / "s.npy", s)
    script = (f"import numpy as np, mmrl; from mmrl import _core; from mmrl.compress.model import CompressedModel; "
              f"cc = CompressedModel({str(trained)!r}, mmrl.Database.load({str(tmp_path / 'db.npz')!r})); "
              f"s = np.load({str(tmp_path / 's.npy')!r}); "
              f"np.savez({str(tmp_path / 'out.npz')!r}, k=_core.mlp_kernel(), d=cc.core.decode(s), t=cc.core.step(s), "
              f"p=cc.core.project(np.ascontiguousarray(s[:, :27])))")
    db.save(tmp_path / "db.npz")
    subprocess.run([sys.executable, "-c", script], check=True, env={**os.environ, "MMRL_NO_F16C": "1"})
    out = np.load(tmp_path / "out.npz")
    assert str(out["k"]) == "widening"
    from mmrl import _core

    if _core.mlp_kernel() != "f16c":
        print("this CPU has no F16C: both sides ran the widening kernel")
    np.testing.assert_array_equal(out["d"], cc.core.decode(s))
    np.testing.assert_array_equal(out["t"], cc.core.step(s))
    np.testing.assert_array_equal(out["p"], cc.core.project(np.ascontiguousarray(s[:, :27])))


def test_the_full_path_plays_the_projector_and_the_stepper(db, trained):
    """Each decision against its rule computed here with torch: the continuation unless the
    projection is closer to the query by more than the transition cost; the rows shown are the
    chosen state stepped and decoded; the character's root is the env's, frame by frame."""
    from mmrl.compress.model import CompressedModel
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import FullPath, policy_actions
    from mmrl.tasks import get_task

    cc = CompressedModel(trained, db)
    task = get_task("plane")
    run = FullPath(task, db, compressed=cc, seed=1, ik=False, foot_locking=False, inertialization_halflife=0.0)
    pol = JoystickPolicy(db)
    env = run.env._core
    # An episode starts from its database frame's state: the frame's features and its
    # compressor latent, normalized.
    frame = int(run.env.env_state(0)["frame"])
    data = CompressData.from_database(db, 0)
    with torch.no_grad():
        z = cc.networks["compressor"]((torch.as_tensor(data.y[frame:frame + 1]) - torch.as_tensor(cc.y_mean)) /
                                      torch.as_tensor(cc.y_std)).numpy()[0]
    np.testing.assert_array_equal(env.compressed_state(0)[:27], db.normalized_features[frame])
    np.testing.assert_allclose(env.compressed_state(0)[27:], (z - cc.z_mean) / cc.z_std, atol=1e-5)
    low, high = run.env.single_action_space.low, run.env.single_action_space.high
    transitions = 0
    for _ in range(60):
        before = env.compressed_state(0).copy()
        action = policy_actions(pol, run.obs[None], layout=run.env.observation_layout).reshape(-1)
        query = np.concatenate([before[:15], np.clip(action, low, high)]).astype(np.float32)
        proj = cc.core.project(query[None])[0]
        stay, jump = ((query - before[:27]) ** 2).sum(), ((query - proj[:27]) ** 2).sum()
        out = run.step(action)
        transition = bool(run.env._step_transitions[0])
        if abs(stay - jump) > 1e-3:
            assert transition == (jump < stay), (stay, jump)
        transitions += transition
        chosen = env.compressed_chosen(0)
        np.testing.assert_array_equal(chosen, proj if transition else before)
        rows, states = [], chosen[None].copy()
        for _k in range(run.config.frames_per_step + 1):
            rows.append(cc.decode(states)[0])
            states = cc.core.step(states)
        np.testing.assert_allclose(env.compressed_rows(0), np.array(rows), atol=1e-5)
        if not out["done"]:
            assert run.root_error()[1] == 0.0  # the character's root is the env's
            # IK and inertialization off: the joints below the roots show the decoded rotations.
            J = db.num_joints
            last = rows[-1][:6 * J].reshape(J, 3, 2)
            from mmrl.compress.pose import quat_to_matrix

            shown = quat_to_matrix(out["res"].local_rotations[-1])[..., :2]
            child = [j for j, p in enumerate(db.parents) if p >= 0 and j != db.joint_names.index(db.roles["hips"])]
            a = last[child] / np.linalg.norm(last[child][..., 0], axis=-1)[..., None, None]
            np.testing.assert_allclose(shown[child][..., 0], a[..., 0], atol=1e-4)
    assert transitions > 0
    rec = run.recording()
    assert (rec["frames"] == -1).all() and rec["natural_motion"].shape[0] == rec["positions"].shape[0] - 1


def test_a_compressed_controller_is_refused_with_the_reason(db, trained, tmp_path):
    from mmrl.compress.model import CompressedModel
    from mmrl.rollout import FullPath
    from mmrl.tasks import get_task

    cc = CompressedModel(trained, db)
    with pytest.raises(ValueError, match="keeps to no tags"):
        FullPath(get_task("plane"), db, compressed=cc, request="gait=walk")
    state = load_compressed(trained)
    state["stage"], state["iteration"] = "projector", 5
    partial = tmp_path / "partial.pt"
    torch.save(state, partial)
    with pytest.raises(CompressedFileError, match="partial.pt: its training stopped in the projector stage"):
        CompressedModel(partial, db)
    broken = dict(load_compressed(trained))
    broken["stepper"] = {k: v[:, :3] if v.ndim == 2 else v for k, v in broken["stepper"].items()}
    bad = tmp_path / "bad-stepper.pt"
    torch.save(broken, bad)
    with pytest.raises(CompressedFileError, match="stepper does not fit"):
        CompressedModel(bad, db)


def test_mmrl_play_steers_a_compressed_character(db, trained):
    """The live session (mmrl play --compressed): a click acts at the next decision, the IK and
    inertialization switches keep the character where it stands, a request is refused."""
    from mmrl.compress.model import CompressedModel
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.tasks import get_task
    from mmrl.viewer.live import LiveSession

    t = get_task("plane")
    s = LiveSession(t, db, JoystickPolicy.preset(db, "joystick"), config=t.default_config(),
                    compressed=CompressedModel(trained, db))
    try:
        x, z, _ = s.root
        s.set_target(x + 3.0, z)
        for _ in range(7):  # one decision and its frames, then the next decision reads the target
            s.step()
        np.testing.assert_allclose(s.run.target, (x + 3.0, z))
        s.set_options(ik=False)
        before = s.root
        s.step()
        assert np.hypot(s.root[0] - before[0], s.root[1] - before[1]) < 0.2  # no jump to a new start
        with pytest.raises(ValueError, match="keeps to no tags"):
            s.set_request("gait=walk")
    finally:
        s.close()


def test_a_finished_file_retrains_one_stage(tmp_path):
    """--stages projector: a fresh projector with the whole budget; the other networks stay."""
    db = mmrl.default_database()
    out = tmp_path / "c.pt"
    cfg = CompressConfig(iterations=100, hidden=(32, 32), latent=8, checkpoint_every=1000, batch=64,
                         **{**QUICK, "stepper_iterations": 50, "projector_iterations": 50})
    train_compressed(db, out, cfg, progress=False)
    before = load_compressed(out)
    more = CompressConfig(**{**cfg.__dict__, "projector_iterations": 120})
    train_compressed(db, out, more, progress=False, stages=["projector"])
    after = load_compressed(out)
    assert after["stage"] == "done" and after["projector_iterations"] == 120
    for key in ("compressor", "decompressor", "stepper"):
        for name, tensor in before[key].items():
            torch.testing.assert_close(after[key][name], tensor, rtol=0, atol=0)
    assert any(not torch.equal(after["projector"][n], t) for n, t in before["projector"].items())
    with pytest.raises(ValueError, match="retrains the stepper and the projector too"):
        train_compressed(db, out, more, progress=False, stages=["decompressor"])
    with pytest.raises(ValueError, match="expected some of"):
        train_compressed(db, out, more, progress=False, stages=["nothing"])


def test_the_start_database_keeps_windows_of_the_database(db):
    """A compressed controller file keeps start windows: every frame equals its source frame, the
    normalization is the database's, and a database without tags works too (Mixamo here)."""
    from mmrl.export.compressed_export import WINDOW, start_database

    small, source = start_database(db, 5)
    assert small.num_frames == 5 * WINDOW and source.shape == (5 * WINDOW,)
    np.testing.assert_array_equal(small.normalized_features, np.asarray(db.normalized_features)[source])
    np.testing.assert_array_equal(np.asarray(small.bone_rotations), np.asarray(db.bone_rotations)[source])
    assert np.flatnonzero(small.valid_mask).tolist() == [k * WINDOW for k in range(5)]
    assert all(db.valid_mask[source[k * WINDOW]] for k in range(5))


def test_the_obstacles_task_plays_a_compressed_controller(db, trained):
    """Moving obstacles with a compressed controller: the env's collisions, hit points and
    sensor maps follow the compressed character (its root is the env's), and the task's tests
    of the played path read the chosen state's trajectory."""
    from mmrl.compress.model import CompressedModel
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import FullPath, policy_actions
    from mmrl.tasks import get_task

    task = get_task("obstacles")
    cc = CompressedModel(trained, db)
    run = FullPath(task, db, compressed=cc, seed=2, stage=10, ik=False, foot_locking=False)
    pol = JoystickPolicy(db)
    endings = {"success": 0, "collision": 0, "other": 0}
    steps = 0
    while sum(endings.values()) < 4 and steps < 2000:
        out = run.step(policy_actions(pol, run.obs[None], layout=run.env.observation_layout).reshape(-1))
        steps += 1
        if not out["done"]:
            assert run.root_error()[1] == 0.0
        else:
            endings["success" if out["success"] else "collision" if out.get("collision") else "other"] += 1
    assert sum(endings.values()) == 4, endings
    rec = run.last_recording
    assert rec is not None and (rec["frames"] == -1).all()

