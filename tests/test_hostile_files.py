"""Files that only look valid (issue 18, item 5): checkpoints and database npz files carrying
pickled objects are refused with a clear error and never unpickled (a malicious ``__reduce__``
that would create a marker file does not run), and a database of another skeleton given to a
run is refused."""
import pathlib

import numpy as np
import pytest
import torch

import mmrl
from mmrl.rl.checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from mmrl.cli import main
from mmrl.motion.database import DatabaseFileError


class Planted:
    """Unpickling this creates ``marker``: the proof that loading ran code."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return pathlib.Path.touch, (pathlib.Path(self.marker),)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("hostile_files") / "run"
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(out), "--no-progress",
                 "--set", "num_steps=32"]) == 0
    return out


@pytest.mark.parametrize("where", ["top", "rng", "model"])
def test_a_checkpoint_with_a_pickled_object_is_refused_without_running_it(run, tmp_path, capsys, where):
    marker = tmp_path / "ran"
    state = load_checkpoint(run / "latest.pt")
    if where == "top":
        state["extra"] = Planted(marker)
    elif where == "rng":
        state["rng"]["python"] = Planted(marker)
    else:
        state["model"]["actor.0.weight"] = Planted(marker)
    evil_run = tmp_path / "evil"
    evil_run.mkdir()
    (evil_run / "config.json").write_text((run / "config.json").read_text())
    torch.save(state, evil_run / "latest.pt")  # plain torch.save: pickles the object
    for load in (lambda: load_checkpoint(evil_run / "latest.pt"), lambda: mmrl.load_policy(evil_run / "latest.pt"),
                 lambda: mmrl.RunDir(evil_run).policy()):
        with pytest.raises(CheckpointError, match=r"latest\.pt: refused: it holds pickled Python objects"):
            load()
    assert main(["train", "plane", "--resume", str(evil_run), "--steps", "1024", "--no-progress"]) == 2
    assert "refused: it holds pickled Python objects" in capsys.readouterr().err
    assert main(["export", str(evil_run), "-o", str(tmp_path / "c.mmrl")]) == 2
    assert not marker.exists()


def test_a_truncated_checkpoint_is_not_called_pickled(run, tmp_path):
    data = (run / "latest.pt").read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 3])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        load_checkpoint(tmp_path / "cut.pt")


def test_a_database_npz_with_a_pickled_object_array_is_refused_without_running_it(tmp_path, capsys):
    marker = tmp_path / "ran"
    db = mmrl.default_database()
    db.save(tmp_path / "db.npz")
    with np.load(tmp_path / "db.npz") as z:
        arrays = dict(z)
    arrays["clip_names"] = np.array([Planted(marker)] * len(arrays["clip_names"]), dtype=object)
    np.savez(tmp_path / "evil.npz", **arrays)
    with pytest.raises(DatabaseFileError, match=r"evil\.npz: refused: it holds pickled Python objects"):
        mmrl.Database.load(tmp_path / "evil.npz")
    assert main(["db", "info", str(tmp_path / "evil.npz")]) == 2
    assert "refused" in capsys.readouterr().err
    assert main(["train", "plane", "--db", str(tmp_path / "evil.npz"), "--steps", "256", "--out",
                 str(tmp_path / "r"), "--no-progress"]) == 2
    assert not marker.exists()


def _other_skeleton(tmp_path):
    """A database whose skeleton renames the joints (the test_runtime Mixamo case, simplified)."""
    from mmrl.motion.synth import write_dataset

    src = tmp_path / "synth"
    paths = write_dataset(src, num_clips=2, seconds_per_clip=2.0)
    other = tmp_path / "other"
    other.mkdir()
    for p in paths:
        (other / p.name).write_text(p.read_text().replace("Hips", "mixamorig:Hips"))
    db = mmrl.Database.from_bvh(other, roles={"hips": "mixamorig:Hips"})
    db.save(tmp_path / "other.npz")
    return tmp_path / "other.npz"


def test_a_database_of_another_skeleton_given_to_a_run_is_refused(run, tmp_path, capsys):
    other = _other_skeleton(tmp_path)
    assert mmrl.Database.load(other).joint_names != mmrl.default_database().joint_names
    assert main(["eval", str(run), "--db", str(other), "--episodes", "1"]) == 2
    assert "is not the one the run" in capsys.readouterr().err
    # The same data for a joystick (no policy of the run) is fine.
    assert main(["eval", str(run), "--db", str(other), "--episodes", "1", "--policy", "joystick"]) == 0
    # A resumed run whose data file now holds another skeleton.
    copy = tmp_path / "copy"
    assert main(["train", "plane", "--db", str(other), "--steps", "256",
                 "--envs", "8", "--out", str(copy), "--no-progress", "--set", "num_steps=32"]) == 0
    mmrl.default_database().save(other)  # the file changes under the run
    assert main(["train", "plane", "--resume", str(copy), "--steps", "512", "--no-progress"]) == 2
    assert "is not the one the run" in capsys.readouterr().err
    with pytest.raises(mmrl.InputError, match="is not the one the run"):
        mmrl.RunDir(copy).database()


def test_a_policy_with_nan_weights_is_not_exported(tmp_path):
    from mmrl.export.runtime_export import write_controller
    from mmrl.tasks.plane import PlaneConfig
    from test_runtime import random_plane_policy

    policy = random_plane_policy(1)
    with torch.no_grad():
        policy.model.actor[-1].weight[0, 0] = float("nan")
    with pytest.raises(ValueError, match=r"policy: policy\.dense\d\.weight holds NaN or inf"):
        write_controller(tmp_path / "nan.mmrl", mmrl.default_database(), policy, "plane", PlaneConfig())
    assert not list(tmp_path.iterdir())
