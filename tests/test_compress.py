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
    assert y.shape == (db.num_frames, 9 * db.num_joints + 3)
    fk = _positions(torch.as_tensor(y[frames], dtype=torch.float64), list(db.parents), db.num_joints).numpy()
    np.testing.assert_allclose(fk, local, atol=2e-4)
    np.testing.assert_array_equal(y[:, -3:], np.asarray(db.root_deltas, np.float32))


def test_a_short_training_reproduces_held_back_clips(db, tmp_path):
    torch.set_num_threads(1)
    cfg = CompressConfig(iterations=600, hidden=(128, 128), latent=16, holdout_every=4, checkpoint_every=300)
    out = tmp_path / "c.pt"
    res = train_compressed(db, out, cfg, progress=False)
    assert res["iteration"] == 600 and (tmp_path / "c-metrics" / "metrics.csv").is_file()
    assert res["holdout_joint_error_cm"] < HOLDOUT_TOLERANCE_CM
    state = load_compressed(out, db)
    data = CompressData.from_database(db, cfg.holdout_every)
    comp, decomp, _ = networks_from(state, data.y.shape[1])
    frames = data.holdout_frames
    err = joint_errors_cm(data, frames, reconstruct(comp, decomp, data, frames))
    assert err.mean() < HOLDOUT_TOLERANCE_CM
    # Against a reference that knows nothing: the mean pose of the training frames.
    mean = np.repeat(data.y_mean[None], frames.size, 0)
    assert err.mean() < 0.25 * joint_errors_cm(data, frames, mean).mean()


def test_seeded_and_resumed_runs_agree(tmp_path):
    db = mmrl.default_database()
    cfg = CompressConfig(iterations=400, hidden=(32, 32), latent=8, checkpoint_every=200, batch=64)
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    train_compressed(db, a, cfg, progress=False)
    half = CompressConfig(**{**cfg.__dict__, "iterations": 200})
    train_compressed(db, b, half, progress=False)
    train_compressed(db, b, cfg, resume=True, progress=False)
    sa, sb = load_compressed(a), load_compressed(b)
    assert sa["iteration"] == sb["iteration"] == 400
    for key in ("compressor", "decompressor"):
        for name, tensor in sa[key].items():
            torch.testing.assert_close(tensor, sb[key][name], rtol=0, atol=0, msg=f"{key}.{name}")


def test_bad_files_are_refused_with_the_reason(tmp_path, capsys):
    db = mmrl.default_database()
    out = tmp_path / "c.pt"
    assert main(["compress", "-o", str(out), "--iterations", "20", "--set", "hidden=16,16", "--no-progress"]) == 0
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
