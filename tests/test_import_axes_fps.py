"""Import invariances: the same clip written Z up, or at 60/120 fps, builds the same database.

The variants are written here, independently of the package: a small BVH text codec below
reads the channel values, scipy's Rotation turns Euler channels (intrinsic, in listed order:
"Zrotation Xrotation Yrotation" is Rz Rx Ry) into rotations and back.
"""
import re
import warnings
from contextlib import nullcontext
from dataclasses import dataclass, replace
from typing import List

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

import mmrl
from mmrl import synth
from mmrl.motion.bvh import MotionImportWarning
from mmrl.cli import main as cli_main

# Rotates a Y-up world to Z up: +90 degrees about X, (x, y, z) -> (x, -z, y).
Y_TO_Z_UP = Rotation.from_euler("x", 90, degrees=True)
# Tolerances. Measured maxima: Z up 2.8e-5 (synth), 2.8e-5 (other skeleton), 1.4e-5 (Bandai)
# in features and 3.2e-7 in root yaws and deltas; 60 and 120 fps are bit-identical on synth
# data (the originals are copied) and 7e-6 on Bandai (whose 0.0333333 s Frame Time is
# another rate in the last digits). Any real difference is far larger: a 2x speed error
# moves features by ~1.
ATOL_FEATURES = 1e-4  # meters, m/s, unit directions
ATOL_ROOT = 1e-5  # meters and radians


@dataclass
class Clip:
    """A BVH file as text around its channel values (frames x channels, file order)."""

    header: str  # everything up to and including the MOTION line
    channels: List[List[str]]  # per joint, in file order
    frame_time: float
    values: np.ndarray  # float64

    def columns(self, joint):
        start = sum(len(c) for c in self.channels[:joint])
        return {name: start + i for i, name in enumerate(self.channels[joint])}

    def rotation(self, joint):
        cols = self.columns(joint)
        names = [n for n in self.channels[joint] if n.endswith("rotation")]
        seq = "".join(n[0].upper() for n in names)  # upper case = intrinsic
        return Rotation.from_euler(seq, self.values[:, [cols[n] for n in names]], degrees=True)

    def set_rotation(self, joint, rot):
        cols = self.columns(joint)
        names = [n for n in self.channels[joint] if n.endswith("rotation")]
        with warnings.catch_warnings():  # a gimbal-locked triple is still the exact rotation
            warnings.filterwarnings("ignore", "Gimbal lock", UserWarning)
            euler = rot.as_euler("".join(n[0].upper() for n in names), degrees=True)
        self.values[:, [cols[n] for n in names]] = euler

    def position_columns(self, joint):
        cols = self.columns(joint)
        return [cols[a + "position"] for a in "XYZ"]

    def text(self):
        rows = "\n".join(" ".join(repr(float(v)) for v in row) for row in self.values)
        return f"{self.header}\nFrames: {len(self.values)}\nFrame Time: {self.frame_time!r}\n{rows}\n"


def read_clip(text):
    header, motion = re.split(r"\n\s*MOTION\s*\n", text, maxsplit=1)
    channels = [line.split()[2:] for line in header.splitlines() if line.strip().startswith("CHANNELS")]
    lines = [ln for ln in motion.splitlines() if ln.strip()]
    frame_time = float(lines[1].split(":")[1])
    values = np.array([[float(x) for x in ln.split()] for ln in lines[2:]])
    assert values.shape[1] == sum(len(c) for c in channels)
    return Clip(header + "\nMOTION", channels, frame_time, values)


def rotate_world(clip, rot):
    """The same motion in a rotated world: rotate the root's position channels and rotation."""
    out = replace(clip, values=clip.values.copy())
    pos = out.position_columns(0)
    out.values[:, pos] = rot.apply(clip.values[:, pos])
    out.set_rotation(0, rot * clip.rotation(0))
    return out


def to_z_up(clip):
    """The same motion in a Z-up world (as an animation tool exports it)."""
    return rotate_world(clip, Y_TO_Z_UP)


def upsample(clip, factor):
    """Exact interpolation at `factor` times the rate: positions linear, rotations slerp; the
    original frames are kept as they are."""
    frames = len(clip.values)
    t_in = np.arange(frames, dtype=np.float64)
    t_out = np.arange((frames - 1) * factor + 1) / factor
    values = np.stack([np.interp(t_out, t_in, col) for col in clip.values.T], 1)
    out = replace(clip, values=values, frame_time=clip.frame_time / factor)
    for j, names in enumerate(clip.channels):
        if any(n.endswith("rotation") for n in names):
            out.set_rotation(j, Slerp(t_in, clip.rotation(j))(t_out))
    out.values[::factor] = clip.values  # bit-exact originals
    return out


def reskin(clip, names, root_channels, joint_channels, scale):
    """Another skeleton for the same motion: joint names, channel orders, units (x scale)."""
    header = re.sub(r"\b(ROOT|JOINT) (\S+)", lambda m: f"{m.group(1)} {names.get(m.group(2), m.group(2))}", clip.header)
    header = re.sub(r"OFFSET ([-\d.e ]+)", lambda m: "OFFSET " + " ".join(repr(float(v) * scale) for v in m.group(1).split()),
                    header)
    assert len(clip.channels[0]) == 6 and all(len(c) == 3 for c in clip.channels[1:])
    new_channels = [list(root_channels)] + [list(joint_channels)] * (len(clip.channels) - 1)
    lines, k = [], 0
    for line in header.splitlines():
        if line.strip().startswith("CHANNELS"):
            indent = line[: len(line) - len(line.lstrip())]
            line = f"{indent}CHANNELS {len(new_channels[k])} {' '.join(new_channels[k])}"
            k += 1
        lines.append(line)
    out = Clip("\n".join(lines), new_channels, clip.frame_time, np.zeros((len(clip.values), sum(map(len, new_channels)))))
    for j in range(len(clip.channels)):
        old, new = clip.columns(j), out.columns(j)
        for name in clip.channels[j]:
            if name.endswith("position"):
                out.values[:, new[name]] = clip.values[:, old[name]] * scale
        out.set_rotation(j, clip.rotation(j))
    return out


# Mixamo-style names; root "Zposition Xposition Yposition Xrotation Zrotation Yrotation",
# joints "Yrotation Zrotation Xrotation"; meters instead of centimetres.
OTHER_NAMES = {"Hips": "mixamorig:Hips", "UpperLeg_L": "mixamorig:LeftUpLeg", "LowerLeg_L": "mixamorig:LeftLeg",
               "Foot_L": "mixamorig:LeftFoot", "Toes_L": "mixamorig:LeftToeBase", "UpperLeg_R": "mixamorig:RightUpLeg",
               "LowerLeg_R": "mixamorig:RightLeg", "Foot_R": "mixamorig:RightFoot", "Toes_R": "mixamorig:RightToeBase",
               "Spine": "mixamorig:Spine", "Head": "mixamorig:Head"}


def other_skeleton(clip):
    return reskin(clip, OTHER_NAMES, ["Zposition", "Xposition", "Yposition", "Xrotation", "Zrotation", "Yrotation"],
                  ["Yrotation", "Zrotation", "Xrotation"], 0.01)



def other_skeleton_database(tmp_path, clips=((1.4, 0.3), (1.2, -0.5), (3.0, 0.2)), seconds=6.0):
    """A mirrored database of synthetic clips (speed m/s, turn rad/s) rewritten on the second
    skeleton (Mixamo names, other channel orders, meters): the other skeleton features are tested on."""
    import mmrl
    from mmrl import synth

    paths = []
    for k, (speed, turn) in enumerate(clips):
        synth.write_clip(tmp_path / f"c{k}.bvh", speed=speed, turn_rate=turn, seconds=seconds, seed=k)
        path = tmp_path / f"mixamo{k}.bvh"
        path.write_text(other_skeleton(read_clip((tmp_path / f"c{k}.bvh").read_text())).text())
        paths.append(path)
    return mmrl.Database.from_bvh(paths, mirror=True)

def build(path, **kw):
    return mmrl.Database.from_bvh(path, **kw)


def assert_same_database(a, b, what):
    assert a.num_frames == b.num_frames, what
    np.testing.assert_allclose(b.features, a.features, atol=ATOL_FEATURES, err_msg=what)
    np.testing.assert_allclose(b.root_positions, a.root_positions, atol=ATOL_ROOT, err_msg=what)
    np.testing.assert_allclose(np.angle(np.exp(1j * (b.root_yaws - a.root_yaws))), 0, atol=ATOL_ROOT, err_msg=what)
    np.testing.assert_allclose(b.root_deltas, a.root_deltas, atol=ATOL_ROOT, err_msg=what)
    np.testing.assert_array_equal(b.contacts, a.contacts, err_msg=what)


def median_speed(db):
    """Median ground speed over +1 s (30 frames at 30 fps), m/s, as `mmrl db info` prints it."""
    f = db.features[db.valid_mask]
    return float(np.median(np.hypot(f[:, 23], f[:, 24])))


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    """A synthetic run (3.5 m/s, turning) on the synth skeleton and on another skeleton, and
    a straight run along +Z (Y up), which a Z-up file turns into a run straight up."""
    out = tmp_path_factory.mktemp("clips")
    synth.write_clip(out / "run.bvh", speed=3.5, turn_rate=0.4, seconds=6.0, seed=1)
    run = read_clip((out / "run.bvh").read_text())
    synth.write_clip(out / "straight.bvh", speed=3.5, seconds=6.0, seed=1)
    straight = read_clip((out / "straight.bvh").read_text())
    hips = mmrl.load_bvh(out / "straight.bvh").global_positions()[:, 0]
    heading = np.arctan2(*(hips[-1] - hips[0])[[0, 2]])  # yaw of the run about +Y
    straight = rotate_world(straight, Rotation.from_euler("y", -heading))
    return {"synth": run, "other": other_skeleton(run), "straight": straight}


def write(tmp_path, name, clip):
    path = tmp_path / name
    path.write_text(clip.text())
    return path


@pytest.mark.parametrize("skeleton", ["synth", "other"])
def test_z_up_file_builds_the_same_database(tmp_path, clips, skeleton):
    y_path = write(tmp_path, "y.bvh", clips[skeleton])
    z_path = write(tmp_path, "z.bvh", to_z_up(clips[skeleton]))
    ref = build(y_path)
    assert mmrl.load_bvh(y_path).up_axis == "y" and mmrl.load_bvh(z_path).up_axis == "z"
    for kw in ({}, {"up": "z"}):
        db = build(z_path, **kw)
        assert_same_database(ref, db, f"{skeleton} Z up {kw}")
        assert list(db.clip_source_up) == ["z"]
    assert_same_database(ref, build(y_path, up="y"), f"{skeleton} explicit Y")
    assert 3.3 < median_speed(ref) < 3.7


@pytest.mark.parametrize("skeleton", ["straight", "other"])
def test_z_up_read_as_y_up_warns(tmp_path, clips, skeleton):
    """Read without the conversion, a Z-up run goes up: a warning naming the file."""
    z_path = write(tmp_path, "z.bvh", to_z_up(clips[skeleton]))
    assert 3.3 < median_speed(build(z_path)) < 3.7
    # Running along the file's Y axis has no ground speed at all: the database warns about that too.
    slow = pytest.warns(MotionImportWarning, match="median speed") if skeleton == "straight" else nullcontext()
    with slow, pytest.warns(MotionImportWarning, match=r"z\.bvh.*(lies flat|vertically).*up='z'"):
        wrong = build(z_path, up="y")
    if skeleton == "straight":
        assert median_speed(wrong) < 0.1


def test_flat_skeleton_warns(tmp_path, clips):
    """A skeleton lying on its side (rolled 90 degrees about the forward axis) warns, naming the file."""
    lying = replace(clips["synth"], values=clips["synth"].values.copy())
    lying.set_rotation(0, Rotation.from_euler("z", 90, degrees=True) * lying.rotation(0))
    path = write(tmp_path, "lying.bvh", lying)
    with pytest.warns(MotionImportWarning, match=r"lying\.bvh.*lies flat"):
        mmrl.load_bvh(path)
    with pytest.warns(MotionImportWarning, match=r"lying\.bvh.*lies flat"):
        build(path)


@pytest.mark.parametrize("skeleton", ["synth", "other"])
def test_60_and_120_fps_build_the_same_database(tmp_path, clips, skeleton):
    clip = clips[skeleton]
    ref = build(write(tmp_path, "30.bvh", clip))
    for factor in (2, 4):
        path = write(tmp_path, f"{30 * factor}.bvh", upsample(clip, factor))
        db = build(path)
        assert db.fps == pytest.approx(30.0, rel=1e-5)
        assert_same_database(ref, db, f"{skeleton} at {30 * factor} fps")
        np.testing.assert_allclose(db.clip_source_fps, [30 * factor])
        # Kept at its own rate, the +30-frame trajectory spans 1/factor s: the task changes.
        native = build(path, fps=None)
        assert native.fps == pytest.approx(30.0 * factor, rel=1e-5)
        assert median_speed(native) == pytest.approx(median_speed(ref) / factor, rel=0.05)


@pytest.mark.parametrize("fps", [24, 25])
def test_non_integer_rate_ratios(tmp_path, fps):
    """24 and 25 fps clips resample to 30 fps (no input frame on most output times)."""
    synth.write_clip(tmp_path / "ref.bvh", speed=2.0, seconds=6.0, seed=2)
    synth.write_clip(tmp_path / "clip.bvh", speed=2.0, seconds=6.0, fps=fps, seed=2)
    ref, db = build(tmp_path / "ref.bvh"), build(tmp_path / "clip.bvh")
    src = mmrl.load_bvh(tmp_path / "clip.bvh")
    assert db.num_frames == (src.num_frames - 1) * 30 // fps + 1
    assert db.fps == pytest.approx(30.0, rel=1e-5)
    np.testing.assert_allclose(db.clip_source_fps, [fps])
    assert median_speed(db) == pytest.approx(median_speed(ref), rel=0.01)  # measured: equal to 1e-3


def test_real_clip_z_up_and_60_fps(tmp_path, shared_data):
    """One real clip (Bandai, 6 channels on every joint, a ground root joint) in both
    orientations and at 60 fps."""
    clip = read_clip((shared_data / "normal" / "dataset-2_run_normal_001.bvh").read_text())
    ref = build(write(tmp_path, "y.bvh", clip))
    assert_same_database(ref, build(write(tmp_path, "z.bvh", to_z_up(clip))), "Bandai Z up")
    assert_same_database(ref, build(write(tmp_path, "60.bvh", upsample(clip, 2))), "Bandai 60 fps")
    assert median_speed(ref) > 2.0


def test_db_info_reports_source_rate_and_axis(tmp_path, clips, capsys):
    path = write(tmp_path, "run60z.bvh", upsample(to_z_up(clips["synth"]), 2))
    assert cli_main(["db", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "1 of 1 clips resampled from 60 fps to 30 fps" in out
    assert "1 of 1 clips were Z up" in out
    speed = float(re.search(r"speed \+1 s\s+median ([\d.]+) m/s", out).group(1))
    assert 3.3 < speed < 3.7
    out_path = tmp_path / "db.npz"
    assert cli_main(["db", "build", str(path), "-o", str(out_path), "--fps", "60", "--up", "z"]) == 0
    db = mmrl.Database.load(out_path)
    assert db.fps == pytest.approx(60.0, rel=1e-5) and list(db.clip_source_up) == ["z"]


def test_old_database_files_still_load(tmp_path, clips):
    """Files saved before the import metadata existed have no clip_source_* arrays."""
    db = build(write(tmp_path, "60.bvh", upsample(clips["synth"], 2)))
    db.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as z:
        arrays = {k: z[k] for k in z.files if not k.startswith("clip_source_")}
    np.savez(tmp_path / "old.npz", **arrays)
    old, new = mmrl.Database.load(tmp_path / "old.npz"), mmrl.Database.load(tmp_path / "new.npz")
    np.testing.assert_array_equal(old.features, db.features)
    np.testing.assert_allclose(old.clip_source_fps, [db.fps])
    assert list(old.clip_source_up) == ["y"]
    np.testing.assert_allclose(new.clip_source_fps, [60.0])


def test_bad_import_arguments(tmp_path, clips):
    path = write(tmp_path, "y.bvh", clips["synth"])
    with pytest.raises(ValueError, match="up must be"):
        mmrl.load_bvh(path, up="x")
    with pytest.raises(ValueError, match="fps must be positive"):
        mmrl.load_bvh(path, fps=-30)
    with pytest.raises(ValueError, match="fps must be positive"):
        build(path, fps=0)
    with pytest.raises(ValueError, match="up: expected"):
        mmrl._core.bvh_load(str(path), 0.0, "sideways", 0.0)
