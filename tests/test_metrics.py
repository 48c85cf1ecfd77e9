"""Quality metrics against hand-computed examples."""
import numpy as np
import pytest

from mmrl import _core, metrics
from mmrl import default_database


def test_foot_sliding_hand_computed():
    T = 5
    p = np.zeros((T, 3, 3))
    # Left foot (joint 1) moves 1 cm in x and 10 cm up per frame: only the horizontal part counts.
    p[:, 1, 0] = 0.01 * np.arange(T)
    p[:, 1, 1] = 0.10 * np.arange(T)
    # Right foot (joint 2) moves 3 cm in z per frame, but only frames 3-4 are in contact.
    p[:, 2, 2] = 0.03 * np.arange(T)
    contacts = np.zeros((T, 2), bool)
    contacts[:, 0] = True
    contacts[3:, 1] = True
    # Left: 4 intervals at 30 cm/s; right: 1 interval (3 -> 4) at 90 cm/s.
    assert metrics.foot_sliding(p, contacts, (1, 2), 30.0) == pytest.approx((4 * 30 + 90) / 5)
    assert metrics.foot_sliding(p, np.zeros((T, 2), bool), (1, 2), 30.0) == 0.0
    with pytest.raises(ValueError, match="contacts"):
        metrics.foot_sliding(p, contacts[:3], (1, 2), 30.0)


def test_transitions_per_second():
    assert metrics.transitions_per_second([True, False, False, True, False], 6, 30.0) == pytest.approx(2.0)
    assert metrics.transitions_per_second([], 6, 30.0) == 0.0


def test_pose_jump_is_zero_on_database_playback_and_sees_a_perturbation():
    db = default_database()
    start = int(db.clip_ranges[2, 0]) + 5
    frames = np.arange(start, start + 20, dtype=np.int64)
    q = _core.database_global_positions(db._db, frames).astype(np.float64)
    # Place the clip in another world frame: rotate by 0.7 rad about Y and shift.
    a = 0.7
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    shift = np.array([4.0, 0.0, -1.0])
    p = q @ rot.T + shift
    # Roots: the database's character frames mapped the same way.
    c = db.root_positions[frames] @ rot.T + shift
    roots = np.column_stack([c[:, 0], c[:, 2], db.root_yaws[frames] + a])
    j = metrics.pose_jumps(p, roots, frames, db)
    assert j.shape == (19,) and j.max() < 1e-3
    # Move one joint 5 cm sideways on frame 10 only: jumps of 5 cm into and out of it.
    p2 = p.copy()
    p2[10, 3, 1] += 0.05
    j2 = metrics.pose_jumps(p2, roots, frames, db)
    assert j2[9] == pytest.approx(5.0, abs=1e-3) and j2[10] == pytest.approx(5.0, abs=1e-3)
    assert metrics.max_pose_jump(p2, roots, frames, db) == pytest.approx(5.0, abs=1e-3)
    with pytest.raises(ValueError, match="roots"):
        metrics.pose_jumps(p, roots[:5], frames, db)


def test_body_joints_skip_a_root_dummy(shared_data):
    import mmrl

    db = mmrl.Database.from_bvh(sorted((shared_data / "normal").glob("*_walk_*.bvh"))[0])
    body = metrics.body_joints(db)
    assert 0 not in body and db.joint_names.index("Hips") in body and len(body) == db.num_joints - 1
