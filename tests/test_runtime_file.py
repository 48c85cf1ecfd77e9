"""The controller file (.mmrl, docs/runtime.md): bad files are refused by the Python reader
and by the C++ loader with an error naming the file and what is wrong, never a crash."""
import struct
import zlib

import numpy as np
import pytest

from mmrl import _core
from mmrl.export.runtime_export import controller_sections, read_controller, write_controller
from mmrl.export.runtime_file import ControllerFileError, read_sections, write_sections
from mmrl.tasks.plane import PlaneConfig
from test_runtime import random_plane_policy

import mmrl


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    path = tmp_path_factory.mktemp("file") / "good.mmrl"
    write_controller(path, mmrl.default_database(), random_plane_policy(0), "plane", PlaneConfig())
    return path


def both_refuse(path, pattern):
    """The Python reader and the C++ loader both refuse ``path`` with a message naming it."""
    with pytest.raises(ControllerFileError, match=pattern) as py_error:
        read_controller(path)
    with pytest.raises(_core.ControllerFileError, match=pattern) as cpp_error:
        _core.RuntimeController.load(str(path))
    for error in (py_error, cpp_error):
        assert str(path) in str(error.value)


def patched(tmp_path, good, offset, data, name="bad.mmrl", fix_header_crc=False):
    raw = bytearray(good.read_bytes())
    raw[offset:offset + len(data)] = data
    if fix_header_crc:
        raw[44:48] = struct.pack("<I", zlib.crc32(bytes(raw[:44])))
    path = tmp_path / name
    path.write_bytes(bytes(raw))
    return path


def test_good_file_loads_in_both(good):
    assert read_controller(good).db.num_frames == _core.RuntimeController.load(str(good)).num_frames


def test_truncated_files_are_refused(tmp_path, good):
    raw = good.read_bytes()
    for size in (0, 10, 63, 64, 200, len(raw) // 2, len(raw) - 1):
        path = tmp_path / f"cut{size}.mmrl"
        path.write_bytes(raw[:size])
        both_refuse(path, "truncated")


def test_wrong_version_is_refused(tmp_path, good):
    both_refuse(patched(tmp_path, good, 8, struct.pack("<I", 2)), "version 2.*reads version 1.*mmrl export")


def test_wrong_endianness_is_refused(tmp_path, good):
    both_refuse(patched(tmp_path, good, 12, struct.pack(">I", 0x0A0B0C0D)), "big-endian")


def test_not_a_controller_file(tmp_path, good):
    both_refuse(patched(tmp_path, good, 0, b"PK\x03\x04xxxx"), "not an mmrl controller file")
    with pytest.raises(_core.ControllerFileError, match="cannot open"):
        _core.RuntimeController.load(str(tmp_path / "missing.mmrl"))


def test_corrupt_bytes_are_refused(tmp_path, good):
    raw = good.read_bytes()
    # A flipped byte in the header, the section table and in the data of a few sections.
    both_refuse(patched(tmp_path, good, 30, bytes([raw[30] ^ 1])), "corrupt header")
    both_refuse(patched(tmp_path, good, 64 + 10, bytes([raw[74] ^ 1])), "corrupt section table")
    sections = read_sections(good)
    table = raw[64:64 + 128 * len(sections)]
    for k in (0, len(sections) // 2, len(sections) - 1):
        name = table[128 * k:128 * k + 64].rstrip(b"\0").decode()
        offset, size = struct.unpack_from("<QQ", table, 128 * k + 104)
        if size:
            at = offset + size // 2
            both_refuse(patched(tmp_path, good, at, bytes([raw[at] ^ 0x40]), name=f"flip{k}.mmrl"),
                        f"section '{name}'.*checksum")


def test_every_single_byte_flip_of_the_header_and_table_is_refused(tmp_path, good):
    raw = good.read_bytes()
    n = 64 + 128 * len(read_sections(good))
    path = tmp_path / "flip.mmrl"
    for at in range(0, n, 7):
        path.write_bytes(raw[:at] + bytes([raw[at] ^ 0x10]) + raw[at + 1:])
        with pytest.raises(_core.ControllerFileError):
            _core.RuntimeController.load(str(path))


def test_inconsistent_but_well_formed_files_are_refused(tmp_path):
    db = mmrl.default_database()
    sections = controller_sections(db, random_plane_policy(0), "plane", PlaneConfig())
    cases = {
        "missing": ({k: v for k, v in sections.items() if k != "policy.header"}, "missing section 'policy.header'"),
        "shape": (dict(sections, **{"db.root_yaws": np.zeros(3, np.float32)}), "root_yaws"),
        "dtype": (dict(sections, **{"db.parents": np.zeros(db.num_joints, np.float32)}), "'db.parents' is float32"),
        "layers": (dict(sections, **{"policy.dense1.weight": np.zeros((32, 31), np.float32)}),
                   "'policy.dense1.weight' does not take 32 inputs"),
        "valid": (dict(sections, **{"db.valid": np.zeros(db.num_frames, np.uint8)}), "'db.valid' disagrees"),
        "task": (dict(sections, **{"task.keys": ["a"], "task.values": np.zeros(1)}), "lacks 'frames_per_step'"),
    }
    for name, (secs, pattern) in cases.items():
        path = tmp_path / f"{name}.mmrl"
        write_sections(path, secs)
        with pytest.raises(_core.ControllerFileError, match=pattern):
            _core.RuntimeController.load(str(path))
