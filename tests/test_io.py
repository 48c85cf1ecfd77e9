"""mmrl.io: atomic writes replace the file whole or leave it untouched, in the documented order."""
from __future__ import annotations

import os

import pytest

from mmrl import io as mmrl_io
from mmrl.io import atomic_open, atomic_write_bytes, atomic_write_text


def test_writes_and_replaces_whole_files(tmp_path):
    path = tmp_path / "config.json"
    assert atomic_write_text(path, "first\n") == path
    assert path.read_text() == "first\n"
    atomic_write_text(path, "second, longer\n")
    assert path.read_text() == "second, longer\n"
    atomic_write_bytes(path, b"\x00\xffbytes")
    assert path.read_bytes() == b"\x00\xffbytes"
    with atomic_open(path, "w", newline="") as file:
        file.write("a,b\r\n")
    assert path.read_bytes() == b"a,b\r\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.json"]


def test_new_files_get_the_permissions_of_a_plain_open(tmp_path):
    atomic_write_text(tmp_path / "atomic.txt", "x")
    (tmp_path / "plain.txt").write_text("x")
    assert (tmp_path / "atomic.txt").stat().st_mode == (tmp_path / "plain.txt").stat().st_mode


@pytest.mark.parametrize("error", [OSError("disk full"), KeyboardInterrupt()])
def test_an_error_mid_write_leaves_the_old_file_and_no_temp_file(tmp_path, error):
    path = tmp_path / "latest.csv"
    path.write_text("old\n")
    with pytest.raises(type(error)):
        with atomic_open(path, "w") as file:
            file.write("half of the new")
            raise error
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["latest.csv"]


def test_data_is_fsynced_before_the_rename_and_the_directory_after(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(mmrl_io.os, "fsync", lambda fd: (events.append("fsync"), real_fsync(fd))[1])
    monkeypatch.setattr(mmrl_io.os, "replace", lambda a, b: (events.append("replace"), real_replace(a, b))[1])
    atomic_write_text(tmp_path / "f.txt", "x")
    assert events == ["fsync", "replace", "fsync"]  # file data, rename, directory entry


def test_bad_mode_and_missing_directory_are_refused(tmp_path):
    for mode in ("a", "r", "w+", "ab"):
        with pytest.raises(ValueError, match="mode"):
            with atomic_open(tmp_path / "f", mode):
                pass
    with pytest.raises(ValueError, match="text mode"):
        with atomic_open(tmp_path / "f", "wb", encoding="utf-8"):
            pass
    with pytest.raises(FileNotFoundError, match="missing"):
        atomic_write_text(tmp_path / "missing" / "f.txt", "x")
    assert list(tmp_path.iterdir()) == []
