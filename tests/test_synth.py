"""Tests of mmrl.motion.synth: determinism, skeleton, planted feet, commanded speeds and turn rates.

The clips are checked with a small independent BVH reader and forward kinematics written here
(any channel order, 3 or 6 channels, positions replace the offset), and, once mmrl's own
loader and Database exist, against their features.
"""
import json
import re

import numpy as np
import pytest

import mmrl
from mmrl import synth

FPS = 30


# ------------------------------------------------------------------------------------------
# A minimal BVH reader and FK, independent of the generator
# ------------------------------------------------------------------------------------------
def _axis_rotation(axis, degrees):
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    i = "XYZ".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3
    r[..., i, i] = 1.0
    r[..., j, j] = c
    r[..., k, k] = c
    r[..., j, k] = -s
    r[..., k, j] = s
    return r


def read_bvh(path):
    """Returns (names, parents, offsets (J, 3), channels per joint, frame_time, values (F, C))."""
    with open(path) as f:
        tokens = re.split(r"\s+", f.read().strip())
    names, parents, offsets, channels = [], [], [], []
    stack, i, in_end_site = [], 0, 0
    while tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            i += 2
        elif tok == "End":
            in_end_site = 1
            i += 2
        elif tok == "{":
            if in_end_site:
                in_end_site += 1
            else:
                stack.append(len(names) - 1)
            i += 1
        elif tok == "}":
            if in_end_site:
                in_end_site = 0
            else:
                stack.pop()
            i += 1
        elif tok == "OFFSET":
            if not in_end_site:
                offsets.append([float(x) for x in tokens[i + 1:i + 4]])
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels.append(tokens[i + 2:i + 2 + n])
            i += 2 + n
        else:
            i += 1
    assert tokens[i + 1] == "Frames:" and tokens[i + 3] == "Frame" and tokens[i + 4] == "Time:"
    num_frames, frame_time = int(tokens[i + 2]), float(tokens[i + 5])
    values = np.array(tokens[i + 6:], dtype=np.float64)
    width = sum(len(c) for c in channels)
    assert values.size == num_frames * width
    return names, parents, np.array(offsets), channels, frame_time, values.reshape(num_frames, width)


def forward_kinematics(path):
    """Global joint positions (F, J, 3) in metres, and joint names, parents and offsets (cm)."""
    names, parents, offsets, channels, frame_time, values = read_bvh(path)
    f = values.shape[0]
    pos = np.zeros((f, len(names), 3))
    rot = np.zeros((f, len(names), 3, 3))
    col = 0
    for j, chans in enumerate(channels):
        local_t = np.broadcast_to(offsets[j], (f, 3)).copy()
        local_r = np.broadcast_to(np.eye(3), (f, 3, 3)).copy()
        for c in chans:
            v = values[:, col]
            col += 1
            if c.endswith("position"):
                local_t[:, "XYZ".index(c[0])] = v  # position channels replace the offset
            else:
                local_r = local_r @ _axis_rotation(c[0], v)  # intrinsic, in the listed order
        p = parents[j]
        if p < 0:
            pos[:, j], rot[:, j] = local_t, local_r
        else:
            pos[:, j] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], local_t)
            rot[:, j] = rot[:, p] @ local_r
    return pos / 100.0, names, parents, offsets, frame_time


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    paths = synth.write_dataset(out, seconds_per_clip=6.0, fps=FPS, seed=3)
    manifest = json.loads((out / "manifest.json").read_text())
    return out, paths, manifest


def _clip_entries(dataset, kinds=None):
    out, paths, manifest = dataset
    for path, entry in zip(paths, manifest["clips"]):
        if kinds is None or entry["kind"] in kinds:
            yield path, entry


def _hip_line_yaw(pos, names):
    """Facing yaw (F,) from the hip line: forward = (UpperLeg_L - UpperLeg_R) x up."""
    d = pos[:, names.index("UpperLeg_L")] - pos[:, names.index("UpperLeg_R")]
    fwd_x, fwd_z = -d[:, 2], d[:, 0]
    return np.unwrap(np.arctan2(fwd_x, fwd_z))


# ------------------------------------------------------------------------------------------
def test_deterministic_per_seed(tmp_path):
    a = synth.write_dataset(tmp_path / "a", num_clips=3, seconds_per_clip=2.0, seed=7)
    b = synth.write_dataset(tmp_path / "b", num_clips=3, seconds_per_clip=2.0, seed=7)
    c = synth.write_dataset(tmp_path / "c", num_clips=3, seconds_per_clip=2.0, seed=8)
    for pa, pb, pc in zip(a, b, c):
        assert pa.read_bytes() == pb.read_bytes()
        assert pa.read_bytes() != pc.read_bytes()
    assert (tmp_path / "a" / "manifest.json").read_bytes() == (tmp_path / "b" / "manifest.json").read_bytes()


def test_manifest_lists_every_clip_with_commands(dataset):
    out, paths, manifest = dataset
    assert len(paths) == synth.DEFAULT_NUM_CLIPS == len(manifest["clips"])
    assert sorted(p.name for p in out.glob("*.bvh")) == sorted(e["file"] for e in manifest["clips"])
    kinds = {e["kind"] for e in manifest["clips"]}
    for needed in ("walk", "run", "walk-turn-left", "walk-turn-right", "run-turn-left", "run-turn-right",
                   "speed-up", "slow-down", "stand", "start", "stop", "step-left", "step-right", "walk-back",
                   "back-stop"):
        assert needed in kinds
    speeds = [e["speed"] for e in manifest["clips"]]
    assert min(s for s in speeds if s > 0) < 0.6 and max(speeds) > 3.8
    for e in manifest["clips"]:
        assert e["frames"] == 6 * FPS
        if "turn" in e["kind"] and "left" in e["kind"]:
            assert e["turn_rate"] > 0
        if "turn" in e["kind"] and "right" in e["kind"]:
            assert e["turn_rate"] < 0
        expected_direction = {"step-left": np.pi / 2, "step-right": -np.pi / 2, "walk-back": np.pi, "back-stop": np.pi}
        assert e["direction"] == expected_direction.get(e["kind"], 0.0)
    total_minutes = sum(e["frames"] for e in manifest["clips"]) / FPS / 60
    assert 2.0 < total_minutes < 4.0


def test_skeleton_and_channels(dataset):
    path, _ = next(_clip_entries(dataset))
    names, parents, offsets, channels, frame_time, values = read_bvh(path)
    assert names == list(synth.JOINT_NAMES)
    assert parents == list(synth.JOINT_PARENTS)
    for required in ("Hips", "Spine", "Chest", "Neck", "Head", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
                     "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R", "Shoulder_L", "UpperArm_L", "LowerArm_L",
                     "Hand_L", "Shoulder_R", "Hand_R"):
        assert required in names
    assert channels[0] == ["Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation"]
    assert all(c == ["Zrotation", "Yrotation", "Xrotation"] for c in channels[1:])
    assert frame_time == pytest.approx(1.0 / FPS, rel=1e-6)
    assert np.all(np.isfinite(values))
    text = path.read_text()
    assert text.count("End Site") == 5


def test_bone_lengths_constant_and_pose_plausible(dataset):
    for path, entry in _clip_entries(dataset):
        pos, names, parents, offsets, _ = forward_kinematics(path)
        for j, p in enumerate(parents):
            if p < 0:
                continue
            length = np.linalg.norm(pos[:, j] - pos[:, p], axis=-1)
            np.testing.assert_allclose(length, np.linalg.norm(offsets[j]) / 100.0, atol=1e-5)
        hips_y = pos[:, names.index("Hips"), 1]
        assert 0.75 < hips_y.min() and hips_y.max() < 1.02, (entry, hips_y.min(), hips_y.max())
        head_y = pos[:, names.index("Head"), 1]
        assert np.all(head_y > 1.3)
        for side in "LR":
            # nothing goes through the floor; the toes rest at 2 cm, the ankle at 8 cm
            assert pos[:, names.index("Toes_" + side), 1].min() > 0.015
            assert pos[:, names.index("Foot_" + side), 1].min() > 0.075


def test_stance_feet_are_planted(dataset):
    for path, entry in _clip_entries(dataset):
        pos, names, *_ = forward_kinematics(path)
        for side, key in (("L", "left"), ("R", "right")):
            intervals = entry["contacts"][key]
            assert intervals, entry
            stance = np.zeros(len(pos), bool)
            for start, stop in intervals:
                stance[start:stop] = True
            for joint in ("Foot_", "Toes_"):
                p = pos[:, names.index(joint + side)]
                speed = np.linalg.norm(np.diff(p, axis=0), axis=-1) * FPS  # m/s between frames
                both = stance[1:] & stance[:-1]
                assert speed[both].max() < 0.01, (entry["file"], joint + side, speed[both].max())
                if entry["speed"] > 0.4:
                    assert speed[~both].max() > 0.5 * entry["speed"]  # the feet do swing


def test_root_speed_and_turn_rate_match_commands(dataset):
    constant = [(p, e) for p, e in _clip_entries(dataset) if e["speed"] == e["speed_end"]]
    assert len(constant) >= 18
    for path, entry in constant:
        pos, names, *_ = forward_kinematics(path)
        hips = pos[:, names.index("Hips")][:, [0, 2]]
        v, w = entry["speed"], entry["turn_rate"]
        window = FPS  # one second
        chord = np.linalg.norm(hips[window:] - hips[:-window], axis=-1)
        # on a circle of turn rate w the 1 s chord is v * sinc(w / 2)
        expected = v * (np.sinc(w / 2.0 / np.pi) if w else 1.0)
        if v == 0:
            assert chord.max() < 0.05, entry
        else:
            assert chord.mean() == pytest.approx(expected, rel=0.05), entry
        yaw = _hip_line_yaw(pos, names)
        rate = (yaw[-1] - yaw[0]) / ((len(yaw) - 1) / FPS)
        assert rate == pytest.approx(w, abs=0.03 + 0.05 * abs(w)), entry


def test_speed_changes_follow_the_ramp(dataset):
    for path, entry in _clip_entries(dataset, kinds={"speed-up", "slow-down", "start", "stop"}):
        pos, names, *_ = forward_kinematics(path)
        hips = pos[:, names.index("Hips")][:, [0, 2]]
        t0, t1 = entry["ramp_seconds"]
        head = slice(0, int(t0 * FPS) + 1)
        tail = slice(int(np.ceil(t1 * FPS)), len(hips))
        for part, v in ((head, entry["speed"]), (tail, entry["speed_end"])):
            seg = hips[part]
            mean_speed = np.linalg.norm(seg[-1] - seg[0]) / ((len(seg) - 1) / FPS)
            assert mean_speed == pytest.approx(v, abs=0.05 + 0.05 * v), entry


def test_write_clip_refuses_bad_input(tmp_path):
    with pytest.raises(ValueError, match="speed"):
        synth.write_clip(tmp_path / "x.bvh", speed=-1.0)
    with pytest.raises(ValueError, match="speed"):
        synth.write_clip(tmp_path / "x.bvh", speed=float("nan"))
    with pytest.raises(ValueError, match="speed_end"):
        synth.write_clip(tmp_path / "x.bvh", speed=1.0, speed_end=9.0)
    with pytest.raises(ValueError, match="turn_rate"):
        synth.write_clip(tmp_path / "x.bvh", speed=1.0, turn_rate=10.0)
    with pytest.raises(ValueError, match="seconds"):
        synth.write_clip(tmp_path / "x.bvh", speed=1.0, seconds=0.1)
    with pytest.raises(ValueError, match="fps"):
        synth.write_clip(tmp_path / "x.bvh", speed=1.0, fps=0)
    with pytest.raises(ValueError, match="num_clips"):
        synth.write_dataset(tmp_path / "d", num_clips=0)
    assert not list(tmp_path.iterdir())  # nothing written on refusal


def test_more_clips_than_the_plan_adds_random_clips(tmp_path):
    n = synth.DEFAULT_NUM_CLIPS + 2
    paths = synth.write_dataset(tmp_path, num_clips=n, seconds_per_clip=2.0, seed=1)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert len(paths) == n
    assert [e["kind"] for e in manifest["clips"][-2:]] == ["random", "random"]


def test_default_dataset_dir_is_generated_once_atomically(tmp_path, monkeypatch):
    monkeypatch.setenv("MMRL_CACHE", str(tmp_path))
    d = synth.default_dataset_dir()
    assert d.parent == tmp_path and d.name == f"synth-v{synth.SYNTH_VERSION}"
    manifest = json.loads((d / "manifest.json").read_text())
    assert len(manifest["clips"]) == synth.DEFAULT_NUM_CLIPS
    total_minutes = sum(e["frames"] for e in manifest["clips"]) / manifest["fps"] / 60
    assert 3.0 <= total_minutes <= 6.0
    assert [p.name for p in tmp_path.iterdir()] == [d.name]  # no temporary directory left behind
    stamp = (d / "manifest.json").stat().st_mtime_ns
    assert synth.default_dataset_dir() == d
    assert (d / "manifest.json").stat().st_mtime_ns == stamp  # not regenerated



def test_a_run_is_evaluated_on_the_synthetic_data_it_was_trained_on(tmp_path, monkeypatch):
    """Version 2 (what every run recorded as {"synthetic": true} trained on) is today's first 31
    clips, byte for byte; a new run records today's version; a version this mmrl cannot make is
    refused naming it."""
    from mmrl.errors import InputError
    from mmrl.motion.sources import data_spec, database_from_spec, synthetic_version

    monkeypatch.setenv("MMRL_CACHE", str(tmp_path))
    old, new = synth.default_dataset_dir(2), synth.default_dataset_dir()
    assert old.name == "synth-v2" and json.loads((old / "manifest.json").read_text())["version"] == 2
    old_files, new_files = sorted(old.glob("*.bvh")), sorted(new.glob("*.bvh"))
    assert len(old_files) == 31 and len(new_files) == synth.DEFAULT_NUM_CLIPS > 31
    assert [f.read_bytes() for f in old_files] == [f.read_bytes() for f in new_files[:31]]
    assert data_spec() == {"synthetic": synth.SYNTH_VERSION}
    assert synthetic_version({"synthetic": True}) == synthetic_version({}) == 2
    assert database_from_spec({"synthetic": True}).num_clips == 31
    assert database_from_spec(data_spec()).num_clips == synth.DEFAULT_NUM_CLIPS
    for bad in (1, 99, "3", 2.0):
        with pytest.raises(InputError, match="synthetic data version"):
            synthetic_version({"synthetic": bad})
    with pytest.raises(ValueError, match="data version 1"):
        synth.default_dataset_dir(1)

# ------------------------------------------------------------------------------------------
# Against mmrl's own loader and database (from the BVH/database work on main)
# ------------------------------------------------------------------------------------------
def test_mmrl_loader_agrees_with_reference_fk(dataset):
    for path, _ in list(_clip_entries(dataset))[:4]:
        ours, names, parents, *_ = forward_kinematics(path)
        motion = mmrl.load_bvh(str(path))
        assert list(motion.joint_names) == names
        assert list(motion.parents) == parents
        assert motion.num_frames == len(ours)
        assert motion.fps == pytest.approx(FPS, rel=1e-5)
        np.testing.assert_allclose(np.asarray(motion.global_positions()), ours, atol=1e-4)


def test_database_features_match_commanded_speed_and_turn_rate(dataset):
    entries = [(p, e) for p, e in _clip_entries(dataset) if e["speed"] == e["speed_end"]]
    db = mmrl.Database.from_bvh([str(p) for p, _ in entries])
    features = np.asarray(db.features)
    ranges = np.asarray(db.clip_ranges)
    assert features.shape == (sum(e["frames"] for _, e in entries), 27)
    assert len(ranges) == len(entries)
    for (path, entry), (start, stop) in zip(entries, ranges):
        v, w = entry["speed"], entry["turn_rate"]
        rows = features[start:stop - 30]  # frames whose +30 future is inside the clip
        traj30 = rows[:, 23:25]
        dir30 = rows[:, 25:27]
        expected = v * (np.sinc(w / 2.0 / np.pi) if w else 1.0)
        length = np.linalg.norm(traj30, axis=-1).mean()
        if v == 0:
            assert length < 0.05, entry
        else:
            assert length == pytest.approx(expected, rel=0.05), entry
        if v > 0 and w == 0:  # where it goes, in the character frame (x = left, z = forward): its direction
            heading = np.arctan2(traj30[:, 0], traj30[:, 1])
            assert np.abs(np.angle(np.exp(1j * (heading - entry["direction"])))).max() < 0.1, entry
        # facing at +30 frames (x = left, z = forward): its angle is the turn over one second
        angle = np.arctan2(dir30[:, 0], dir30[:, 1]).mean()
        assert angle == pytest.approx(w * 1.0, abs=0.05 + 0.05 * abs(w)), entry
        if abs(w) > 0.3:
            assert np.sign(angle) == np.sign(w)
