"""What a run killed at the worst moment leaves behind, one deterministic case per defect that
tests/test_kill_resume.py found (each fails on the code before the fix)."""
import os
import time
from pathlib import Path

import pytest

from _toyenv import PointMassTargetVecEnv, quiet_config, read_rows
from mmrl import io
from mmrl.rl import checkpoints
from mmrl.rl.checkpoints import load_checkpoint
from mmrl.cli import main
from mmrl.motion.database import find_bvh_files
from mmrl.rl.ppo import train


def _die_inside_atomic_write(path: Path) -> None:
    """A forked child opens an atomic write of ``path``, writes half, and dies (os._exit: no
    cleanup runs, as with SIGKILL)."""
    pid = os.fork()
    if pid == 0:
        try:
            with io.atomic_open(path, "wb") as file:
                file.write(b"HIERARCHY\nROOT Hips\n")
                file.flush()
                os._exit(0)
        finally:
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 0


def test_a_killed_write_leaves_no_file_a_directory_scan_takes_for_a_clip(tmp_path):
    (tmp_path / "walk.bvh").write_text("whole file")
    _die_inside_atomic_write(tmp_path / "run.bvh")
    leftovers = [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert len(leftovers) == 1 and not leftovers[0].name.endswith(".bvh")  # ".run.bvh.<random>.tmp"
    assert find_bvh_files(tmp_path) == [tmp_path / "walk.bvh"]
    (tmp_path / "._walk.bvh").write_text("a macOS resource fork, or an older mmrl's temp file")
    assert find_bvh_files(tmp_path) == [tmp_path / "walk.bvh"]


def test_remove_stale_temps_removes_a_killed_writers_leftovers_only(tmp_path):
    target = tmp_path / "latest.pt"
    _die_inside_atomic_write(target)
    _die_inside_atomic_write(tmp_path / "other.pt")
    (tmp_path / ".latest.pt.keep").write_text("not a temp file")
    assert io.remove_stale_temps(target, min_age_s=60) == []  # too young: maybe a live writer's
    old = time.time() - 120
    for p in tmp_path.glob(".latest.pt.*.tmp"):
        os.utime(p, (old, old))
    removed = io.remove_stale_temps(target, min_age_s=60)
    assert len(removed) == 1 and not removed[0].exists()
    assert sorted(p.name[:10] for p in tmp_path.iterdir()) == [".latest.pt", ".other.pt."]


def test_training_removes_the_temp_files_of_a_killed_checkpoint_write(tmp_path):
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=256), tmp_path)
    _die_inside_atomic_write(tmp_path / "latest.pt")
    assert [p for p in tmp_path.iterdir() if p.name.startswith(".latest.pt.")]
    train(PointMassTargetVecEnv(4), quiet_config(total_steps=512), tmp_path, resume=True)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".latest.pt.")]


def test_a_fresh_run_into_a_directory_left_before_the_first_checkpoint_starts_a_new_metrics_file(tmp_path):
    # A run killed after logging its first rows but before its first checkpoint leaves metrics.csv
    # and no latest.pt; the next fresh run used to append its rows (and a second header) to them.
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=512), tmp_path)
    (tmp_path / "latest.pt").unlink()
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=512), tmp_path)
    assert [int(r["step"]) for r in read_rows(tmp_path / "metrics.csv")] == [256, 512]
    assert (tmp_path / "metrics.csv").read_text().count("step,wall_s") == 1


def test_resume_drops_a_torn_last_metrics_row(tmp_path):
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=512), tmp_path)
    with open(tmp_path / "metrics.csv", "a") as file:  # a power loss in the middle of the row of step 384
        file.write("38")
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=1024), tmp_path, resume=True)
    assert [int(r["step"]) for r in read_rows(tmp_path / "metrics.csv")] == [256, 512, 768, 1024]


class Killed(BaseException):
    """Stands for SIGKILL: nothing after it runs (not even train's Ctrl-C handler)."""


def test_a_kill_between_the_snapshot_and_latest_pt_never_loses_the_snapshot(tmp_path, monkeypatch):
    # latest.pt lists the snapshots already saved; written before the snapshot, a kill between
    # the two left a latest.pt that lists snapshot_512.pt, which the resumed run never writes.
    real_save, calls = checkpoints.save_checkpoint, []

    def save_then_die(state, path):
        calls.append(Path(path).name)
        if len(calls) == 3:  # the second file of the save at step 512 (latest.pt at 256 came first)
            raise Killed
        return real_save(state, path)

    monkeypatch.setattr(checkpoints, "save_checkpoint", save_then_die)
    with pytest.raises(Killed):
        train(PointMassTargetVecEnv(8), quiet_config(total_steps=1024, checkpoint_interval_steps=1,
                                                    snapshot_steps=(512,)), tmp_path)
    monkeypatch.undo()
    for s in load_checkpoint(tmp_path / "latest.pt")["snapshots"]:
        assert (tmp_path / f"snapshot_{s}.pt").exists()
    train(PointMassTargetVecEnv(8), quiet_config(total_steps=1024, checkpoint_interval_steps=1,
                                                snapshot_steps=(512,)), tmp_path, resume=True)
    assert load_checkpoint(tmp_path / "snapshot_512.pt")["global_step"] == 512


def test_resume_of_a_run_killed_before_its_first_checkpoint_starts_at_step_0(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "plane", "--steps", "512", "--envs", "8", "--out", str(run), "--no-progress",
                 "--set", "num_steps=32"]) == 0
    for p in run.glob("*.pt"):  # as if killed during its first iteration: config.json, no checkpoint
        p.unlink()
    assert main(["train", "plane", "--resume", str(run), "--steps", "512", "--no-progress"]) == 0
    assert "no checkpoint yet" in capsys.readouterr().out
    assert [int(r["step"]) for r in read_rows(run / "metrics.csv")] == [256, 512]
    assert load_checkpoint(run / "latest.pt")["global_step"] == 512
