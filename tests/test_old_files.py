"""Files written before issue 23 (the flat package layout, the old config names, controller
files without ``task.core``) still load and run. tests/data/main-a161603 holds them, written by
main at a161603:

- ``plane-run/``: ``mmrl train plane --steps 4096 --seed 0`` on the synthetic data (config.json,
  latest.pt, metrics.csv);
- ``plane.mmrl``: ``mmrl export`` of a plane run on four synthetic BVH clips (960 frames)."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.cli import main
from mmrl.export.runtime_export import read_controller
from mmrl.runs import RunDir
from runtime_helpers import drive_both

OLD = Path(__file__).parent / "data" / "main-a161603"


@pytest.fixture()
def old_run(tmp_path):
    run = tmp_path / "plane-run"
    shutil.copytree(OLD / "plane-run", run)
    return run


def test_an_old_run_evaluates_and_resumes(old_run, capsys):
    r = RunDir(old_run)
    policy = r.policy()
    obs = np.zeros((3, 17), np.float32)
    assert policy.act(obs).shape == (3, 12)
    assert main(["eval", str(old_run), "--episodes", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["episodes"] == 3
    assert main(["train", "plane", "--resume", str(old_run), "--steps", "8192", "--no-progress"]) == 0
    rows = (old_run / "metrics.csv").read_text().splitlines()
    steps = [int(line.split(",")[0]) for line in rows[1:]]
    assert steps == sorted(steps) and steps[-1] == 8192 and len(set(steps)) == len(steps)


def test_an_old_controller_file_loads_and_decides_as_the_full_path():
    path = OLD / "plane.mmrl"
    back = read_controller(path)
    assert "task.core" not in back.sections and back.task_name == "plane"
    c = _core.RuntimeController.load(str(path))
    assert c.task_name == "plane" and c.obs_dim == 17
    config = mmrl.get_task("plane").default_config().replace(
        **{k: type(getattr(mmrl.get_task("plane").default_config(), k))(v) for k, v in back.task.items()})
    out = drive_both(path, mmrl.get_task("plane"), back.db, config, c.act, 300)
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5 and out["obs_error"] == 0.0


def test_checkpoints_naming_a_network_by_its_flat_layout_path_still_resolve():
    from mmrl.rl.networks import ObstacleActorCritic, PlaneActorCritic, network_class

    assert network_class("mmrl.networks:PlaneActorCritic") is PlaneActorCritic
    assert network_class("mmrl.networks:ObstacleActorCritic") is ObstacleActorCritic
    with pytest.raises(KeyError):
        network_class("mmrl.networks:NoSuchNet")


def test_saved_databases_keep_their_format_name(tmp_path):
    """The npz's format name is the file format's, not a module path: moving the module must not
    make every saved database unreadable."""
    db = mmrl.default_database()
    db.save(tmp_path / "db.npz")
    with np.load(tmp_path / "db.npz") as z:
        assert str(z["format"]) == "mmrl.database"
    assert mmrl.Database.load(tmp_path / "db.npz").num_frames == db.num_frames


def test_the_old_names_of_renamed_things_still_work_and_warn():
    """One name per concept: mmrl.Controller is mmrl.Character, _core.TargetTaskConfig is
    _core.PlaneTaskConfig; the old names stay for one release."""
    with pytest.warns(DeprecationWarning, match="mmrl.Character"):
        old = mmrl.Controller
    assert old is mmrl.Character
    assert _core.TargetTaskConfig is _core.PlaneTaskConfig
    c = old(mmrl.default_database(), fast=True)
    assert c.step(np.zeros(12, np.float32)).frames.shape == (6,)
