"""The C interface (cpp/capi/mmrl_runtime.h, libmmrl_runtime_c) through ctypes: it equals the C++
runtime and the Python full path over 1,000 decisions, and the runtime through a stick; every
error path returns its code and message, it serves characters on several threads at once, and
the library exports only mmrl_ symbols. CI builds the library (.ci/run's cmake build) and runs this file again against an ASan
build (tools/hardening.sh, $MMRL_CAPI_LIB); elsewhere the tests look in build/*/ and skip if it is
not built."""
import ctypes as C
import shutil
import subprocess
import threading
import zlib
from pathlib import Path

import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.export.runtime_export import write_controller
from mmrl.tasks.plane import PlaneConfig
from runtime_helpers import built_artifact, drive_both
from test_runtime import random_plane_policy

OK, INVALID, FILE, VERSION, NULL, SMALL = 0, 1, 2, 3, 4, 5


class Decision(C.Structure):
    _fields_ = [("count", C.c_int64), ("frames_before", C.c_int64), ("match", C.c_int64), ("transition", C.c_int32),
                ("root_x", C.c_float), ("root_z", C.c_float), ("root_yaw", C.c_float), ("target_x", C.c_float),
                ("target_z", C.c_float), ("cost", C.c_float)]


def library_path() -> Path:
    return built_artifact("MMRL_CAPI_LIB", "libmmrl_runtime_c.so", "MMRL_BUILD_CAPI=ON")


@pytest.fixture(scope="module")
def lib():
    L = C.CDLL(str(library_path()))
    P, F, I32, I64, S = C.c_void_p, C.c_float, C.c_int32, C.c_int64, C.c_char_p
    fp = C.POINTER(C.c_float)
    sig = {
        "mmrl_api_version": ([], I32), "mmrl_file_version": ([], I32), "mmrl_last_error": ([], S),
        "mmrl_status_name": ([C.c_int], S),
        "mmrl_controller_load": ([S, C.POINTER(P)], C.c_int),
        "mmrl_controller_load_memory": ([C.c_char_p, C.c_size_t, S, C.POINTER(P)], C.c_int),
        "mmrl_controller_destroy": ([P], None), "mmrl_controller_last_error": ([P], S),
        "mmrl_controller_num_joints": ([P, C.POINTER(I32)], C.c_int),
        "mmrl_controller_joint_name": ([P, I32, C.c_char_p, C.c_size_t, C.POINTER(C.c_size_t)], C.c_int),
        "mmrl_controller_joint_parent": ([P, I32, C.POINTER(I32)], C.c_int),
        "mmrl_controller_fps": ([P, fp], C.c_int),
        "mmrl_controller_frames_per_step": ([P, C.POINTER(I32)], C.c_int),
        "mmrl_controller_start_frame": ([P, I64, C.POINTER(I64)], C.c_int),
        "mmrl_character_create": ([P, F, F, F, I64, C.POINTER(P)], C.c_int),
        "mmrl_character_destroy": ([P], None), "mmrl_character_last_error": ([P], S),
        "mmrl_character_set_target": ([P, F, F], C.c_int),
        "mmrl_character_set_stick": ([P, F, F, F], C.c_int),
        "mmrl_character_set_facing": ([P, F], C.c_int),
        "mmrl_character_set_request": ([P, S], C.c_int),
        "mmrl_character_update": ([P, F, fp, fp, I32, fp], C.c_int),
        "mmrl_character_root": ([P, fp], C.c_int),
        "mmrl_character_last_decision": ([P, C.POINTER(Decision)], C.c_int),
    }
    for name, (args, res) in sig.items():
        f = getattr(L, name)
        f.argtypes, f.restype = args, res
    return L


def floats(a):
    return a.ctypes.data_as(C.POINTER(C.c_float))


@pytest.fixture(scope="module")
def controller_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("capi") / "plane.mmrl"
    write_controller(path, mmrl.default_database(), random_plane_policy(2), "plane", PlaneConfig(transition_cost=5.0))
    return path


def load(lib, path):
    h = C.c_void_p()
    assert lib.mmrl_controller_load(str(path).encode(), C.byref(h)) == OK, lib.mmrl_last_error()
    return h


def create(lib, ctl, x=0.0, z=0.0, yaw=0.0, frame=-1):
    h = C.c_void_p()
    assert lib.mmrl_character_create(ctl, x, z, yaw, frame, C.byref(h)) == OK, lib.mmrl_controller_last_error(ctl)
    return h


def test_versions_and_skeleton(lib, controller_file):
    assert lib.mmrl_api_version() == 1 and lib.mmrl_file_version() == 1
    assert lib.mmrl_status_name(FILE) == b"MMRL_ERROR_FILE"
    ctl = load(lib, controller_file)
    db = mmrl.default_database()
    n = C.c_int32()
    assert lib.mmrl_controller_num_joints(ctl, C.byref(n)) == OK and n.value == db.num_joints
    buf, need = C.create_string_buffer(64), C.c_size_t()
    names, parents = [], []
    for j in range(n.value):
        assert lib.mmrl_controller_joint_name(ctl, j, buf, 64, C.byref(need)) == OK
        names.append(buf.value.decode())
        p = C.c_int32()
        assert lib.mmrl_controller_joint_parent(ctl, j, C.byref(p)) == OK
        parents.append(p.value)
    assert names == db.joint_names and parents == db.parents
    lib.mmrl_controller_destroy(ctl)


def test_the_c_interface_equals_the_runtime_and_the_full_path(lib, controller_file):
    """1,000 decisions: the C interface's frames and poses equal the C++ runtime's (the binding)
    bit for bit, and the runtime's matches equal the Python full path's (drive_both)."""
    db = mmrl.default_database()
    config = PlaneConfig(transition_cost=5.0)
    ref = drive_both(controller_file, mmrl.get_task("plane"), db, config, _core.RuntimeController.load(
        str(controller_file)).act, 1000)
    np.testing.assert_array_equal(ref["rt_matches"], ref["py_matches"])
    # The same character through the C interface and through the binding, same start and targets.
    from runtime_helpers import scripted_targets
    from mmrl.rollout import FullPath

    fp = FullPath(mmrl.get_task("plane"), db, config=config, seed=0, record=False, continuous=True)
    x, z, yaw = fp.character.root
    ctl = load(lib, controller_file)
    ch = create(lib, ctl, x, z, yaw, fp.character.frame)
    rt = _core.RuntimeCharacter(_core.RuntimeController.load(str(controller_file)), x, z, yaw, fp.character.frame)
    targets = scripted_targets(1001, 0)
    J = db.num_joints
    rot, tr, root = np.zeros((J, 4), np.float32), np.zeros((J, 3), np.float32), np.zeros(3, np.float32)
    t = 0
    lib.mmrl_character_set_target(ch, *targets[0])
    rt.set_target(*targets[0])
    matches = []
    for _ in range(1000):
        r = rt.root
        if np.hypot(r[0] - targets[t][0], r[1] - targets[t][1]) < 0.5:
            t += 1
            lib.mmrl_character_set_target(ch, *targets[t])
            rt.set_target(*targets[t])
        for _ in range(6):
            assert lib.mmrl_character_update(ch, 1.0 / 30.0, floats(rot), floats(tr), J, floats(root)) == OK
            rt.update(1.0 / 30.0)
            np.testing.assert_array_equal(rot, rt.local_rotations())
            np.testing.assert_array_equal(tr, rt.local_translations())
            np.testing.assert_array_equal(root, np.float32(rt.root))
        d = Decision()
        assert lib.mmrl_character_last_decision(ch, C.byref(d)) == OK
        matches.append(d.match)
    np.testing.assert_array_equal(matches, ref["rt_matches"])
    lib.mmrl_character_destroy(ch)
    lib.mmrl_controller_destroy(ctl)


def test_every_error_path_returns_its_code_and_message(lib, controller_file, tmp_path):
    h = C.c_void_p(123)
    assert lib.mmrl_controller_load(str(tmp_path / "none.mmrl").encode(), C.byref(h)) == FILE
    assert h.value is None and b"none.mmrl" in lib.mmrl_last_error()
    bad = tmp_path / "bad.mmrl"
    bad.write_bytes(b"MMRLCTRL" + bytes(100))
    assert lib.mmrl_controller_load(str(bad).encode(), C.byref(h)) == FILE and b"bad.mmrl" in lib.mmrl_last_error()
    # Another format version (the header's checksum made right, so the version is what is wrong).
    data = bytearray(controller_file.read_bytes())
    data[8:12] = (7).to_bytes(4, "little")
    data[44:48] = zlib.crc32(bytes(data[:44])).to_bytes(4, "little")
    other = tmp_path / "v7.mmrl"
    other.write_bytes(bytes(data))
    assert lib.mmrl_controller_load(str(other).encode(), C.byref(h)) == VERSION
    assert b"version 7" in lib.mmrl_last_error()
    assert lib.mmrl_controller_load_memory(bytes(data), len(data), b"mem", C.byref(h)) == VERSION
    # NULL handles and pointers.
    assert lib.mmrl_controller_load(None, C.byref(h)) == NULL and b"path is NULL" in lib.mmrl_last_error()
    assert lib.mmrl_character_set_target(None, 0.0, 0.0) == NULL and b"character is NULL" in lib.mmrl_last_error()
    n = C.c_int32()
    assert lib.mmrl_controller_num_joints(None, C.byref(n)) == NULL
    lib.mmrl_controller_destroy(None)
    lib.mmrl_character_destroy(None)
    ctl = load(lib, controller_file)
    ch = create(lib, ctl)
    J = mmrl.default_database().num_joints
    rot = np.zeros((J, 4), np.float32)
    # A buffer too small, and a joint name that does not fit.
    assert lib.mmrl_character_update(ch, 0.1, floats(rot), None, J - 1, None) == SMALL
    assert b"the skeleton has" in lib.mmrl_character_last_error(ch)
    assert lib.mmrl_character_update(ch, 0.1, None, None, J, None) == NULL
    need = C.c_size_t()
    assert lib.mmrl_controller_joint_name(ctl, 0, C.create_string_buffer(1), 1, C.byref(need)) == SMALL
    assert need.value == len(mmrl.default_database().joint_names[0]) + 1
    assert lib.mmrl_controller_joint_name(ctl, 999, C.create_string_buffer(8), 8, None) == INVALID
    # NaN targets, a bad dt, an unknown tag: the message says what is wrong; the character goes on.
    assert lib.mmrl_character_set_target(ch, float("nan"), 0.0) == INVALID
    assert b"finite" in lib.mmrl_character_last_error(ch)
    assert lib.mmrl_character_update(ch, -1.0, floats(rot), None, J, None) == INVALID
    assert lib.mmrl_character_set_request(ch, b"gait=fly") == INVALID
    assert b"gait=run|walk" in lib.mmrl_character_last_error(ch)
    assert lib.mmrl_character_set_request(ch, b"gait=walk") == OK
    assert lib.mmrl_character_update(ch, 0.5, floats(rot), None, J, None) == OK
    assert np.allclose(np.linalg.norm(rot, axis=1), 1.0, atol=1e-5)
    lib.mmrl_character_destroy(ch)
    # Destroying the controller first is allowed: a character keeps it alive.
    ch = create(lib, ctl)
    lib.mmrl_controller_destroy(ctl)
    assert lib.mmrl_character_update(ch, 0.2, floats(rot), None, J, None) == OK
    lib.mmrl_character_destroy(ch)


def test_the_c_stick_equals_the_runtimes_and_refuses_bad_values(lib, controller_file):
    """mmrl_character_set_stick: through a stick, a target and a stick again, the C interface's
    poses and roots equal the C++ runtime's (the binding, whose stick tests/test_runtime.py holds
    to the joystick's full path) bit for bit. A zero or non-finite direction, or a speed not
    finite and > 0, is MMRL_ERROR_INVALID_ARGUMENT naming the argument, and changes nothing."""
    ctl = load(lib, controller_file)
    ch = create(lib, ctl, 2.0, -1.0, 0.7, 500)
    rt = _core.RuntimeCharacter(_core.RuntimeController.load(str(controller_file)), 2.0, -1.0, 0.7, 500)
    J = mmrl.default_database().num_joints
    rot, tr, root = np.zeros((J, 4), np.float32), np.zeros((J, 3), np.float32), np.zeros(3, np.float32)
    nan, inf = float("nan"), float("inf")
    walked = []
    for kind, args in [("stick", (0.0, -2.0, 1.0)), ("target", (6.0, 3.0)), ("stick", (3.0, 1.0, 2.5))]:
        if kind == "stick":
            assert lib.mmrl_character_set_stick(ch, *args) == OK
            rt.set_stick(*args)
        else:
            assert lib.mmrl_character_set_target(ch, *args) == OK
            rt.set_target(*args)
        # Refused values on the C side only: the two characters must stay equal.
        for bad in [(0.0, 0.0, 1.0), (nan, 1.0, 1.0), (1.0, -inf, 1.0)]:
            assert lib.mmrl_character_set_stick(ch, *bad) == INVALID
            assert b"direction (x, z) must be finite and not zero" in lib.mmrl_character_last_error(ch)
        for speed in (0.0, -1.0, nan, inf):
            assert lib.mmrl_character_set_stick(ch, 1.0, 0.0, speed) == INVALID
            assert b"speed must be finite and > 0" in lib.mmrl_character_last_error(ch)
            assert b"speed" in lib.mmrl_last_error()
        start = np.array(rt.root)
        for _ in range(100 * 6):
            assert lib.mmrl_character_update(ch, 1.0 / 30.0, floats(rot), floats(tr), J, floats(root)) == OK
            rt.update(1.0 / 30.0)
            np.testing.assert_array_equal(rot, rt.local_rotations())
            np.testing.assert_array_equal(tr, rt.local_translations())
            np.testing.assert_array_equal(root, np.float32(rt.root))
        assert rt.last_decision()["stick"] == (kind == "stick")
        walked.append(root[:2] - start[:2])
    # Not vacuous: each stick took the character its way (20 s at 1 and 2.5 m/s).
    assert walked[0] @ (0.0, -1.0) > 10.0 and walked[2] @ (np.array([3.0, 1.0]) / np.hypot(3.0, 1.0)) > 25.0, walked
    assert lib.mmrl_character_set_stick(None, 1.0, 0.0, 1.0) == NULL and b"character is NULL" in lib.mmrl_last_error()
    lib.mmrl_character_destroy(ch)
    lib.mmrl_controller_destroy(ctl)


def test_an_arrive_controller_takes_a_facing_in_radians_and_equals_the_runtime(lib, controller_file, tmp_path):
    """The arrive task (a plug-in core) through the C interface: no decision before a facing
    (MMRL_ERROR_INVALID_ARGUMENT naming it), a non-finite facing refused, a plane controller
    refuses one; with a facing its poses and roots equal the C++ runtime's bit for bit."""
    db = mmrl.default_database()
    path = tmp_path / "arrive.mmrl"
    write_controller(path, db, random_plane_policy(3, 19), "arrive", mmrl.get_task("arrive").default_config())
    ctl = load(lib, path)
    ch = create(lib, ctl, 0.0, 0.0, 0.0, 500)
    rt = _core.RuntimeCharacter(_core.RuntimeController.load(str(path)), 0.0, 0.0, 0.0, 500)
    J = db.num_joints
    rot, tr, root = np.zeros((J, 4), np.float32), np.zeros((J, 3), np.float32), np.zeros(3, np.float32)
    assert lib.mmrl_character_set_target(ch, 0.0, 0.0) == OK
    rt.set_target(0.0, 0.0)
    assert lib.mmrl_character_update(ch, 1.0 / 30.0, floats(rot), floats(tr), J, floats(root)) == INVALID
    assert b"needs a facing" in lib.mmrl_character_last_error(ch)
    assert lib.mmrl_character_set_facing(ch, float("nan")) == INVALID
    assert b"facing must be finite (radians)" in lib.mmrl_character_last_error(ch)
    assert lib.mmrl_character_set_facing(ch, 2.0) == OK
    rt.set_facing(2.0)
    for _ in range(60 * 6):
        assert lib.mmrl_character_update(ch, 1.0 / 30.0, floats(rot), floats(tr), J, floats(root)) == OK
        rt.update(1.0 / 30.0)
        np.testing.assert_array_equal(rot, rt.local_rotations())
        np.testing.assert_array_equal(root, np.float32(rt.root))
    plane = load(lib, controller_file)
    other = create(lib, plane)
    assert lib.mmrl_character_set_facing(other, 1.0) == INVALID
    assert b"has no target facing" in lib.mmrl_character_last_error(other)
    for h in (ch, other):
        lib.mmrl_character_destroy(h)
    for h in (ctl, plane):
        lib.mmrl_controller_destroy(h)


def test_memory_load_and_threads(lib, controller_file):
    """Characters of one controller on four threads at once (ctypes releases the GIL) make the
    same frames as the same characters one after another."""
    data = controller_file.read_bytes()
    ctl = C.c_void_p()
    assert lib.mmrl_controller_load_memory(data, len(data), b"plane", C.byref(ctl)) == OK
    J = mmrl.default_database().num_joints

    def drive(i, out):
        ch = create(lib, ctl, float(i), 0.0, 0.0, 40 * i)
        lib.mmrl_character_set_target(ch, float(i) + 3.0, 4.0)
        rot = np.zeros((J, 4), np.float32)
        frames = []
        for _ in range(300):
            assert lib.mmrl_character_update(ch, 1.0 / 30.0, floats(rot), None, J, None) == OK
            d = Decision()
            lib.mmrl_character_last_decision(ch, C.byref(d))
            frames.append(d.match)
        lib.mmrl_character_destroy(ch)
        out[i] = frames

    alone, together = {}, {}
    for i in range(4):
        drive(i, alone)
    threads = [threading.Thread(target=drive, args=(i, together)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert alone == together and len(set(map(tuple, alone.values()))) == 4
    lib.mmrl_controller_destroy(ctl)


def test_the_library_exports_only_mmrl_symbols_and_links_only_the_c_and_cpp_runtimes():
    path = library_path()
    nm = shutil.which("nm")
    if nm is None:
        pytest.fail("nm (binutils) is needed to read the symbol table")
    out = subprocess.run([nm, "-D", "--defined-only", str(path)], capture_output=True, text=True, check=True).stdout
    names = [line.split()[-1] for line in out.splitlines() if line.strip()]
    assert names and all(n.startswith("mmrl_") for n in names), [n for n in names if not n.startswith("mmrl_")]
    assert {"mmrl_controller_load", "mmrl_character_update", "mmrl_character_set_request",
            "mmrl_character_set_stick"} <= set(names)
    needed = subprocess.run(["readelf", "-d", str(path)], capture_output=True, text=True, check=True).stdout
    libs = {line.split("[")[1].split("]")[0] for line in needed.splitlines() if "(NEEDED)" in line}
    runtimes = ("libstdc++", "libm.", "libgcc_s", "libc.", "libpthread", "ld-linux", "libasan", "libubsan")
    assert all(lib.startswith(runtimes) for lib in libs), libs
