"""Mirrored clips keep the skeleton's joint bases (database.hpp, mirror_corrections), so a
transition between an original clip and a mirrored one blends two poses of the same skeleton.

The reference: the same motion written on a skeleton whose every joint frame is turned by a
constant rotation B (offsets B^-1 t, local rotations B^-1 r B: the same world motion, a rest
pose that is no longer mirror-symmetric in world X, as Bandai-Namco's bones lie along their
local X). Mirroring must not depend on that choice: the mirrored clip of the turned skeleton,
turned back (B r' B^-1), equals the mirrored clip of the upright one, and keeps its offsets.
Before the fix its hips' local rotation came out 180 degrees off and its offsets flipped."""
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mmrl
from mmrl import synth
from test_database import mirror_features
from test_import_axes_fps import read_clip

B = Rotation.from_euler("ZX", [90, 30], degrees=True)  # every joint frame turned by this


def turned_text(text):
    """The BVH text of the same motion with every joint frame turned by B."""
    clip = read_clip(text)
    lines = clip.header.splitlines()
    # Offsets are in the parent's frame: t' = B^-1 t (the root's, and end sites', likewise).
    binv = B.inv()
    for k, line in enumerate(lines):
        m = re.match(r"(\s*)OFFSET (.*)", line)
        if m:
            t = binv.apply(np.array([float(v) for v in m.group(2).split()]))
            lines[k] = f"{m.group(1)}OFFSET " + " ".join(repr(float(v)) for v in t)
    out = type(clip)("\n".join(lines), clip.channels, clip.frame_time, clip.values.copy())
    for j in range(len(clip.channels)):
        r = clip.rotation(j)
        out.set_rotation(j, r * B if j == 0 else binv * r * B)
    return out.text()


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    d = tmp_path_factory.mktemp("turned")
    texts = []
    for k, (speed, turn) in enumerate(((1.3, 0.4), (2.8, -0.3), (1.1, -0.6))):
        synth.write_clip(d / f"c{k}.bvh", speed=speed, turn_rate=turn, seconds=4.0, seed=k)
        texts.append((d / f"c{k}.bvh").read_text())
    return texts


def database(texts, turned):
    motions = [mmrl.parse_bvh(turned_text(t) if turned else t, f"c{k}.bvh") for k, t in enumerate(texts)]
    return mmrl.Database.from_motions(motions, mirror=True)


def test_mirrored_clips_keep_the_joint_bases_of_any_rest_pose(clips):
    upright, turned = database(clips, False), database(clips, True)
    n = upright.num_clips // 2
    assert list(turned.clip_mirrored) == [False] * n + [True] * n
    # The same world motion: features equal, and the mirrored clips are the originals' mirror images.
    np.testing.assert_allclose(turned.features, upright.features, atol=2e-4)
    for c in range(n):
        (a0, a1), (b0, b1) = turned.clip_ranges[c], turned.clip_ranges[n + c]
        np.testing.assert_allclose(turned.features[b0:b1], mirror_features(turned.features[a0:a1]), atol=2e-4)
    # The mirror keeps the skeleton's offsets: every mirrored frame's joint translations (below
    # the root) equal the original frames'.
    start = turned.clip_ranges[n][0]
    np.testing.assert_allclose(turned.bone_translations[start:, 1:], turned.bone_translations[:start, 1:][:1].repeat(
        turned.num_frames - start, 0), atol=1e-5)
    # ... and the joint bases: turned back, its local rotations are the upright skeleton's mirror's.
    q_turned = Rotation.from_quat(turned.bone_rotations[start:].reshape(-1, 4)[:, [1, 2, 3, 0]])
    q_upright = Rotation.from_quat(upright.bone_rotations[start:].reshape(-1, 4)[:, [1, 2, 3, 0]])
    j = np.tile(np.arange(turned.num_joints), turned.num_frames - start)
    back = [(q_turned[k] * B.inv()) if j[k] == 0 else (B * q_turned[k] * B.inv()) for k in range(len(j))]
    err = np.array([(b * u.inv()).magnitude() for b, u in zip(back, q_upright)])
    assert np.degrees(err.max()) < 0.05, np.degrees(err.max())
    # Not vacuous: the turned skeleton's mirrored hips do differ from the upright one's as stored.
    assert np.degrees((q_turned[j == 0] * q_upright[j == 0].inv()).magnitude()).min() > 10


def test_a_transition_into_a_mirrored_clip_moves_no_further_than_within_the_originals(clips):
    """Pose jumps measured by the full path: the turned skeleton's mirrored database plays as
    smoothly as the upright one's (the same world motion, the same joystick episodes)."""
    task = mmrl.get_task("plane")
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import evaluate_full_path

    res = {}
    for turned in (False, True):
        db = database(clips, turned)
        res[turned] = evaluate_full_path(task, db, JoystickPolicy.preset(db, "joystick"), episodes=8, seed=2)
    assert res[True]["transitions_per_s"] > 0.5
    assert res[True]["pose_jump_p99_cm"] == pytest.approx(res[False]["pose_jump_p99_cm"], rel=0.05, abs=0.2)
    assert res[True]["foot_sliding_ik_off_cm_per_s"] == pytest.approx(res[False]["foot_sliding_ik_off_cm_per_s"],
                                                                      rel=0.05, abs=0.2)
