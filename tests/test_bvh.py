"""BVH import: parsing, units, FK and every malformed-input case."""
import random

import numpy as np
import pytest

import mmrl

GOOD = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 95 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Spine
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 70 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 95 0 0 0 0 0 0 0
10 95 0 0 90 0 0 0 0
"""
# Line numbers in GOOD: 16 = MOTION, 17 = Frames, 18 = Frame Time, 19-20 = frame lines.


def parse(text, scale=None):
    return mmrl.parse_bvh(text, "test.bvh", scale=scale)


def test_parse_and_fk_hand_computed():
    m = parse(GOOD)
    assert m.joint_names == ["Hips", "Spine"]
    assert m.parents == [-1, 0]
    assert m.num_frames == 2
    assert m.fps == pytest.approx(30.0, rel=1e-4)
    assert m.scale == pytest.approx(0.01)  # 175 cm tall -> centimeters
    g = m.global_positions()
    assert g.shape == (2, 2, 3) and g.dtype == np.float32
    np.testing.assert_allclose(g[0, 0], [0, 0.95, 0], atol=1e-6)
    np.testing.assert_allclose(g[0, 1], [0, 1.05, 0], atol=1e-6)
    # Frame 2: hips at x = 0.1 m, rotated 90 degrees about X: the spine offset (0, 0.1, 0)
    # maps to (0, 0, 0.1).
    np.testing.assert_allclose(g[1, 0], [0.1, 0.95, 0], atol=1e-6)
    np.testing.assert_allclose(g[1, 1], [0.1, 0.95, 0.1], atol=1e-6)


def test_explicit_scale_and_meters_inference():
    m = parse(GOOD, scale=1.0)
    assert m.global_positions()[0, 0, 1] == pytest.approx(95.0)
    meters = GOOD.replace("OFFSET 0 95 0", "OFFSET 0 0.95 0").replace("OFFSET 0 10 0", "OFFSET 0 0.1 0")
    meters = meters.replace("OFFSET 0 70 0", "OFFSET 0 0.7 0")
    meters = meters.replace("0 95 0 0 0 0 0 0 0\n10 95 0 0 90", "0 0.95 0 0 0 0 0 0 0\n0.1 0.95 0 0 90")
    m = parse(meters)
    assert m.scale == 1.0
    np.testing.assert_allclose(m.global_positions()[1, 0], [0.1, 0.95, 0], atol=1e-6)


def test_whitespace_variants_parse_identically():
    ref = parse(GOOD).global_positions()
    crlf = GOOD.replace("\n", "\r\n")
    spaces = GOOD.replace("\t", "    ")
    blank = GOOD.replace("MOTION\n", "\n\nMOTION\n\n").replace("0 0 0 0\n10", "0 0 0 0\n\n\n10") + "\n\n"
    for text in (crlf, spaces, blank):
        np.testing.assert_allclose(parse(text).global_positions(), ref, atol=1e-6)


def test_three_channel_root_and_any_order():
    text = GOOD.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
                        "CHANNELS 3 Yrotation Xrotation Zrotation")
    text = text.replace("0 95 0 0 0 0 0 0 0", "0 0 0 0 0 0").replace("10 95 0 0 90 0 0 0 0", "0 90 0 0 0 0")
    m = parse(text)
    g = m.global_positions()
    # Root stays at its OFFSET; frame 2 rotates 90 degrees about X.
    np.testing.assert_allclose(g[1, 1], [0, 0.95, 0.1], atol=1e-6)


def error(text, match=None):
    with pytest.raises(mmrl.BVHError, match=match) as info:
        parse(text)
    e = info.value
    assert isinstance(e, ValueError)
    assert e.file == "test.bvh"
    assert str(e).startswith(f"test.bvh:{e.line}:")
    return e


def test_error_truncated_motion():
    e = error(GOOD.replace("Frames: 2", "Frames: 3"), "truncated")
    assert e.line >= 20


def test_error_wrong_value_count():
    e = error(GOOD.replace("10 95 0 0 90 0 0 0 0", "10 95 0 0 90 0 0 0"), "8 values, expected 9")
    assert e.line == 20


def test_error_unknown_channel():
    e = error(GOOD.replace("Zrotation Xrotation Yrotation\n\t\tEnd", "Zrotation Wrotation Yrotation\n\t\tEnd"),
              "unknown channel name 'Wrotation'")
    assert e.line == 9


@pytest.mark.parametrize("bad", ["abc", "nan", "inf", "-inf", "1e99", "1.2.3"])
def test_error_non_numeric_nan_inf(bad):
    e = error(GOOD.replace("10 95 0 0 90", f"10 95 {bad} 0 90"))
    assert e.line == 20


def test_error_zero_frames():
    e = error(GOOD.replace("Frames: 2", "Frames: 0"), "zero frames")
    assert e.line == 17


def test_error_missing_motion():
    e = error(GOOD.split("MOTION")[0], "missing MOTION")
    assert e.line >= 16


def test_error_unbalanced_braces():
    e = error(GOOD.replace("\t}\n}\nMOTION", "\t}\nMOTION"), "unbalanced braces")
    assert e.line > 0
    e = error(GOOD.replace("}\nMOTION", "}\n}\nMOTION"), "unbalanced braces")
    assert e.line == 16


def test_error_duplicate_joint():
    e = error(GOOD.replace("JOINT Spine", "JOINT Hips"), "duplicate joint name 'Hips'")
    assert e.line == 6


def test_error_empty_and_binary():
    assert error("", "empty file").line == 1
    assert error("   \n\n", None).line >= 1
    e = error("HIERARCHY\x00\x01\x02 binary", "binary")
    assert e.line == 1
    error(bytes(range(256)).decode("latin-1") * 4, "binary")


def test_error_file_not_found(tmp_path):
    with pytest.raises(mmrl.BVHError, match="cannot open"):
        mmrl.load_bvh(tmp_path / "missing.bvh")


def test_bad_scale_argument():
    with pytest.raises(ValueError, match="scale"):
        mmrl.parse_bvh(GOOD, scale=-1.0)


def test_random_corruption_never_crashes():
    """Mutated files either parse or raise BVHError: never crash or hang."""
    rng = random.Random(0)
    tokens = ["{", "}", "JOINT", "End Site", "CHANNELS 7", "OFFSET", "nan", "\x00", "MOTION", "Frames: -1", "x", "\n"]
    for _ in range(400):
        text = list(GOOD)
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(text))
            op = rng.random()
            if op < 0.4:
                del text[i : i + rng.randint(1, 20)]
            elif op < 0.8:
                text.insert(i, rng.choice(tokens))
            else:
                text[i] = chr(rng.randrange(32, 127))
        try:
            parse("".join(text))
        except mmrl.BVHError as e:
            assert e.file == "test.bvh" and e.line >= 0


def test_export_round_trip():
    m = parse(GOOD)
    again = parse(m.to_bvh())
    np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-5)


# Hips with a left and a right leg (frame lines: 6 + 3 + 3 values).
LEGS = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 95 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Leg_L
\t{
\t\tOFFSET 10 -5 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -90 0
\t\t}
\t}
\tJOINT Leg_R
\t{
\t\tOFFSET -10 -5 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -90 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 95 0 0 0 0 0 0 0 0 0 0
10 95 5 0 20 10 30 0 0 -15 5 0
"""


def test_mirror_twice_is_identity():
    m = parse(LEGS)
    mm = m.mirrored().mirrored()
    np.testing.assert_allclose(mm.global_positions(), m.global_positions(), atol=1e-6)
    # The mirror image: x negated, the legs swapped.
    g, g1 = m.global_positions(), m.mirrored().global_positions()
    np.testing.assert_allclose(g1[:, [0, 2, 1], 0], -g[..., 0], atol=1e-6)
    np.testing.assert_allclose(g1[:, [0, 2, 1], 1:], g[..., 1:], atol=1e-6)


def test_mirror_refuses_a_side_joint_without_partner():
    """Mirroring Leg_L onto itself would put the left leg on the right: an error naming it."""
    with pytest.raises(mmrl.JointRoleError, match=r"cannot mirror: no joint on the other side pairs with 'Leg_L' \(left\)"):
        parse(GOOD.replace("JOINT Spine", "JOINT Leg_L")).mirrored()


@pytest.mark.parametrize("name,side,base", [
    # Conventions read before: a side word or letter at either end.
    ("LeftUpLeg", 0, "upleg"), ("RightToeBase", 1, "toebase"), ("mixamorig:LeftFoot", 0, "foot"),
    ("UpperLeg_L", 0, "upperleg"), ("Toes_R", 1, "toes"), ("thigh.L", 0, "thigh"), ("l_foot", 0, "foot"),
    ("LFoot", 0, "foot"), ("RUpLeg", 1, "upleg"), ("LHipJoint", 0, "hipjoint"), ("leftupleg", 0, "upleg"),
    ("footright", 1, "foot"), ("Hips", -1, "hips"), ("Spine1", -1, "spine1"), ("joint_Root", -1, "jointroot"),
    # A side token anywhere (3ds Max Biped, DAZ, any separator or camel case).
    ("Bip01_L_Thigh", 0, "bip01thigh"), ("Bip01 R Calf", 1, "bip01calf"), ("Bip01-L-Toe0", 0, "bip01toe0"),
    ("CC_Base_R_Foot", 1, "ccbasefoot"), ("lThigh", 0, "thigh"), ("HandL", 0, "hand"), ("Bip01_Pelvis", -1, "bip01pelvis"),
    # Not a side: a letter inside a word, or an all-capitals word.
    ("Bip01", -1, "bip01"), ("ROOT", -1, "root"), ("LOWERBACK", -1, "lowerback"), ("Toe0Nub", -1, "toe0nub"),
])
def test_joint_side_tokens(name, side, base):
    assert mmrl._core.joint_side(name) == (side, base)


def test_joint_names_with_spaces_parse_and_round_trip():
    """A name is the rest of the ROOT/JOINT line, trimmed: 'Bip01 L Thigh' keeps its spaces."""
    text = LEGS.replace("ROOT Hips", "ROOT Bip01 Pelvis \t").replace("JOINT Leg_L", "JOINT Bip01 L Thigh")
    text = text.replace("JOINT Leg_R\n\t{", "JOINT Bip01  R Thigh {")  # the brace on the name's line
    m = parse(text)
    assert m.joint_names == ["Bip01 Pelvis", "Bip01 L Thigh", "Bip01  R Thigh"]
    np.testing.assert_allclose(m.global_positions(), parse(LEGS).global_positions(), atol=1e-6)
    again = parse(m.to_bvh())
    assert again.joint_names == m.joint_names
    np.testing.assert_allclose(again.global_positions(), m.global_positions(), atol=1e-5)


def test_error_joint_without_a_name():
    e = error(GOOD.replace("JOINT Spine", "JOINT  "), "JOINT without a joint name")
    assert e.line == 6
    e = error(GOOD.replace("ROOT Hips", "ROOT {"), "ROOT without a joint name")
    assert e.line == 2
