"""Motion database: features, invariances, mirroring, save/load and the real data."""
import re

import numpy as np
import pytest

import mmrl
from mmrl.motion.database import BLOCK_NAMES, FEATURE_BLOCKS

CLIP = "normal/dataset-2_walk-turn-left_normal_001.bvh"


def edit_root_channels(text, fn):
    """Rewrite the first six values (joint_Root's channels) of every frame line."""
    head, motion = text.split("Frame Time:", 1)
    ft_line, *rows = motion.split("\n")
    out = []
    for r in rows:
        v = r.split()
        if v:
            v[:6] = fn([float(x) for x in v[:6]])
            r = " ".join(str(x) for x in v)
        out.append(r)
    return head + "Frame Time:" + "\n".join([ft_line] + out)


def db_from_text(text, name="clip.bvh", **kw):
    return mmrl.Database.from_motions([mmrl.parse_bvh(text, name)], **kw)


@pytest.fixture(scope="module")
def clip_text(shared_data):
    return (shared_data / CLIP).read_text()


def test_features_invariant_to_rotation_and_translation(clip_text):
    ref = db_from_text(clip_text)
    moved = db_from_text(edit_root_channels(clip_text, lambda v: [312.0, 0.0, -245.0, 0.0, 0.0, 123.0]))
    assert np.abs(moved.root_positions - ref.root_positions).max() > 1.0  # it did move
    np.testing.assert_allclose(moved.features, ref.features, atol=2e-4)
    np.testing.assert_allclose(moved.root_deltas, ref.root_deltas, atol=2e-5)
    yaw_change = np.angle(np.exp(1j * (moved.root_yaws - ref.root_yaws)))
    np.testing.assert_allclose(yaw_change, np.radians(123.0), atol=1e-4)


def test_feature_layout_and_units(clip_text):
    db = db_from_text(clip_text)
    f = db.features
    assert f.shape == (db.num_frames, 27) and f.dtype == np.float32
    for k in (17, 21, 25):  # unit facing directions
        np.testing.assert_allclose(np.hypot(f[:, k], f[:, k + 1]), 1.0, atol=1e-5)
    # Feet in meters near the ground and hip-width apart, left foot on +X (left).
    assert 0.0 < np.median(f[:, 1]) < 0.2
    assert np.median(f[:, 0] - f[:, 3]) > 0.05
    # Trajectory at +10 equals the root displacement over 10 frames in the character frame.
    rp, yaw = db.root_positions, db.root_yaws
    i = 40
    d = rp[i + 10] - rp[i]
    c, s = np.cos(yaw[i]), np.sin(yaw[i])
    np.testing.assert_allclose(f[i, 15:17], [c * d[0] - s * d[2], s * d[0] + c * d[2]], atol=1e-5)
    # Hips velocity by central difference, rotated into the character frame.
    assert np.linalg.norm(f[i, 12:15]) == pytest.approx(np.linalg.norm(f[i, 15:17]) * 3, rel=0.3)


def test_valid_mask_and_clip_ranges(shared_data):
    files = sorted((shared_data / "normal").glob("dataset-2_walk_normal_00[1-3].bvh"))
    db = mmrl.Database.from_bvh(files)
    frames = [mmrl.load_bvh(p).num_frames for p in files]
    np.testing.assert_array_equal(db.clip_ranges, np.stack([np.cumsum([0] + frames[:-1]), np.cumsum(frames)], 1))
    expected = np.concatenate([np.arange(n) + 30 < n for n in frames])
    np.testing.assert_array_equal(db.valid_mask, expected)
    assert db.clip_names == [str(p) for p in files]


def test_normalization_blocks(clip_text):
    db = db_from_text(clip_text)
    f = db.features.astype(np.float64)
    mean = f.mean(0)
    norm = db.normalized_features.copy()
    for name, cols, weight in FEATURE_BLOCKS:
        scale = f[:, cols].std(0).mean() / weight
        np.testing.assert_allclose(norm[:, cols], (f[:, cols] - mean[cols]) / scale, atol=2e-4)
    db = db.with_weights({"trajectory_direction": 3.0})
    cols = FEATURE_BLOCKS[BLOCK_NAMES.index("trajectory_direction")][1]
    np.testing.assert_allclose(db.normalized_features[:, cols], 2 * norm[:, cols], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(db.normalize(db.features), db.normalized_features, atol=1e-5)
    with pytest.raises(ValueError, match="unknown feature blocks"):
        db.with_weights({"nope": 1.0})
    with pytest.raises(ValueError, match="positive"):
        db.with_weights({"foot_position": -1.0})


def mirror_features(f):
    """Expected features of the mirror image: x -> -x and left <-> right."""
    m = f.copy()
    m[:, 0:3], m[:, 3:6] = f[:, 3:6], f[:, 0:3]
    m[:, 6:9], m[:, 9:12] = f[:, 9:12], f[:, 6:9]
    for c in (0, 3, 6, 9, 12, 15, 17, 19, 21, 23, 25):
        m[:, c] *= -1
    return m


def test_mirror(clip_text):
    db = db_from_text(clip_text, mirror=True)
    (a0, a1), (b0, b1) = db.clip_ranges
    assert db.num_clips == 2 and list(db.clip_mirrored) == [False, True]
    np.testing.assert_allclose(db.features[b0:b1], mirror_features(db.features[a0:a1]), atol=2e-4)
    m = mmrl.parse_bvh(clip_text, "c.bvh")
    twice = m.mirrored().mirrored()
    np.testing.assert_allclose(twice.global_positions(), m.global_positions(), atol=1e-5)
    d1 = mmrl.Database.from_motions([m])
    d2 = mmrl.Database.from_motions([twice])
    np.testing.assert_allclose(d2.features, d1.features, atol=2e-4)


def test_other_naming_convention(clip_text):
    """A CMU/Mixamo-named copy of the skeleton finds the same roles and features."""
    rename = {"Hips": "mixamorig:Hips", "UpperLeg_L": "mixamorig:LeftUpLeg", "LowerLeg_L": "mixamorig:LeftLeg",
              "Foot_L": "mixamorig:LeftFoot", "Toes_L": "mixamorig:LeftToeBase", "UpperLeg_R": "mixamorig:RightUpLeg",
              "LowerLeg_R": "mixamorig:RightLeg", "Foot_R": "mixamorig:RightFoot", "Toes_R": "mixamorig:RightToeBase"}
    text = re.sub(r"\b(JOINT) (\w+)\b", lambda m: f"JOINT {rename.get(m.group(2), m.group(2))}", clip_text)
    db = db_from_text(text)
    assert db.roles["left_foot"] == "mixamorig:LeftFoot" and db.roles["hips"] == "mixamorig:Hips"
    np.testing.assert_allclose(db.features, db_from_text(clip_text).features, atol=1e-6)


def test_role_detection_failure_and_override(clip_text):
    text = clip_text.replace("JOINT Foot_L", "JOINT Joint17").replace("JOINT Foot_R", "JOINT Joint21")
    with pytest.raises(mmrl.JointRoleError, match="Joint17") as info:
        db_from_text(text)
    assert "joints found" in str(info.value) and "UpperLeg_L" in str(info.value)
    db = db_from_text(text, roles={"left_foot": "Joint17", "right_foot": "Joint21"})
    np.testing.assert_allclose(db.features, db_from_text(clip_text).features, atol=1e-6)
    with pytest.raises(ValueError, match="names no joint"):
        db_from_text(clip_text, roles={"left_foot": "Nope"})


def test_save_load_round_trip(tmp_path, clip_text):
    db = db_from_text(clip_text, mirror=True, weights={"foot_velocity": 2.0})
    path = tmp_path / "db.npz"
    db.save(path)
    back = mmrl.Database.load(path)
    for name in ("features", "normalized_features", "valid_mask", "clip_ranges", "root_positions", "root_yaws",
                 "root_deltas", "bone_translations", "bone_rotations", "feature_scale", "clip_mirrored"):
        np.testing.assert_array_equal(getattr(back, name), getattr(db, name), err_msg=name)
    assert back.joint_names == db.joint_names and back.parents == db.parents
    assert back.roles == db.roles and back.weights == db.weights and back.clip_names == db.clip_names
    assert back.fps == db.fps


def test_load_corrupt_or_foreign(tmp_path, clip_text):
    db = db_from_text(clip_text)
    good = tmp_path / "db.npz"
    db.save(good)
    data = good.read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(mmrl.DatabaseFileError, match="truncated.npz"):
        mmrl.Database.load(bad)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file at all")
    with pytest.raises(mmrl.DatabaseFileError, match="junk.npz"):
        mmrl.Database.load(junk)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(mmrl.DatabaseFileError, match="not an mmrl database"):
        mmrl.Database.load(foreign)
    with np.load(good) as z:
        arrays = dict(z)
    arrays["version"] = np.array(99, np.int32)
    np.savez(tmp_path / "future.npz", **arrays)
    with pytest.raises(mmrl.DatabaseFileError, match="version 99"):
        mmrl.Database.load(tmp_path / "future.npz")
    arrays["version"] = np.array(mmrl.motion.database.FILE_VERSION, np.int32)
    arrays["features"] = arrays["features"][:-5]
    np.savez(tmp_path / "short.npz", **arrays)
    with pytest.raises(mmrl.DatabaseFileError, match="features"):
        mmrl.Database.load(tmp_path / "short.npz")
    assert good.read_bytes() == data  # failed loads never touch the good file


def test_paths_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        mmrl.Database.from_bvh(tmp_path / "nothing")
    with pytest.raises(FileNotFoundError, match="no .bvh"):
        mmrl.Database.from_bvh(tmp_path)


def test_whole_shared_dataset(shared_data, shared_db):
    db = shared_db
    files = sorted(shared_data.rglob("*.bvh"))
    assert db.num_clips == len(files) == 962
    declared = []
    for p in files:
        with open(p) as fh:
            for line in fh:
                if line.startswith("Frames:"):
                    declared.append(int(line.split()[1]))
                    break
    assert db.num_frames == sum(declared) == 149239
    np.testing.assert_array_equal(np.diff(db.clip_ranges, axis=1)[:, 0], declared)
    f = db.features
    assert np.isfinite(f).all()
    speeds = {"walk": [], "run": [], "walk-turn-left": [], "walk-turn-right": []}
    turns = {"walk-turn-left": [], "walk-turn-right": []}
    for (a, b), name in zip(db.clip_ranges, db.clip_names):
        kind = name.split("/")[-1].split("_")[1]
        idx = np.arange(a, b)[db.valid_mask[a:b]]
        speeds[kind].append(np.median(np.hypot(f[idx, 23], f[idx, 24])))  # +30 frames = 1 s
        if kind in turns:
            turns[kind].append(np.degrees(np.arctan2(f[idx, 25], f[idx, 26])).sum() / 30.0)
    assert 1.0 < np.median(speeds["walk"]) < 1.5
    assert 2.4 < np.median(speeds["run"]) < 3.2
    assert np.median(speeds["run"]) > 2 * np.median(speeds["walk"])
    # Turn clips turn about 90 degrees in total, left positive.
    assert 60 < np.median(turns["walk-turn-left"]) < 120
    assert -120 < np.median(turns["walk-turn-right"]) < -60


@pytest.fixture(scope="module")
def synth_db(tmp_path_factory):
    from mmrl import synth

    out = tmp_path_factory.mktemp("synth_weights")
    for i, (speed, turn) in enumerate([(1.2, 0.0), (3.5, 0.0), (1.5, 0.6), (0.0, 0.0), (2.5, -0.5)]):
        synth.write_clip(out / f"clip{i}.bvh", speed=speed, turn_rate=turn, seconds=6.0, seed=i)
    return mmrl.Database.from_bvh(out)


def test_with_weights_leaves_existing_matchers_exact(synth_db):
    """Weights are fixed at build. A matcher (and an env holding it) built before a weight
    change keeps answering exactly like brute force over its own database's rows; the new
    Database's matcher answers like brute force over the new rows. (The old mutating
    set_weights rewrote the rows under a tree built from the old ones: tree and brute force
    then disagreed, silently.)"""
    from mmrl import _core
    from mmrl.tasks.plane import PlaneVectorEnv

    db = synth_db
    env = PlaneVectorEnv(4, db=db)
    matcher = db.matcher
    rows = db.normalized_features.copy()
    rng = np.random.default_rng(0)
    queries = (rows[rng.integers(0, db.num_frames, 400)] + rng.normal(0, 0.7, (400, 27))).astype(np.float32)

    new = db.with_weights({"trajectory_direction": 4.0, "foot_position": 0.2, "hips_velocity": 2.5})
    assert isinstance(new, mmrl.Database) and new is not db
    assert not hasattr(db, "set_weights")
    np.testing.assert_array_equal(db.normalized_features, rows)  # the old database is untouched
    assert db.weights == mmrl.motion.database.DEFAULT_WEIGHTS and new.weights["trajectory_direction"] == 4.0
    assert env.db is db and db.matcher is matcher
    np.testing.assert_array_equal(new.features, db.features)
    assert np.abs(new.normalized_features - rows).max() > 0.5

    for database, m in ((db, matcher), (new, new.matcher)):
        # Reference: an independent brute-force scan over a copy of the database's current rows.
        reference = _core.Matcher(np.array(database.normalized_features), database.valid_mask.copy())
        want_i, want_c = reference.brute_force(queries)
        got_i, got_c = m.match(queries)
        np.testing.assert_array_equal(got_i, want_i)
        np.testing.assert_array_equal(got_c, want_c)
        np.testing.assert_array_equal(database.match(queries, normalized=True)[0], want_i)
    # The weights matter: the two databases answer differently for many queries.
    assert (matcher.match(queries)[0] != new.matcher.match(queries)[0]).mean() > 0.1


def test_with_weights_keeps_import_metadata_and_saves(tmp_path, synth_db):
    new = synth_db.with_weights([1, 1, 1, 1, 1])
    np.testing.assert_array_equal(new.clip_source_fps, synth_db.clip_source_fps)
    np.testing.assert_array_equal(new.clip_source_up, synth_db.clip_source_up)
    new.save(tmp_path / "w.npz")
    back = mmrl.Database.load(tmp_path / "w.npz")
    assert back.weights == {n: 1.0 for n in BLOCK_NAMES}
    np.testing.assert_array_equal(back.normalized_features, new.normalized_features)
