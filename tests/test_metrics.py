"""Quality metrics against hand-computed examples."""
import numpy as np
import pytest

import mmrl
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


# ----------------------------------------------------------------------------- issue 14: each metric once
FPS = 30.0


def test_a_foot_sliding_at_exactly_10_cm_per_s_gives_10_mean_and_p95():
    T = 40
    t = np.arange(T) / FPS
    p = np.zeros((T, 4, 3))
    # Left foot (joint 2): 6 cm/s along x and 8 cm/s along z = 10 cm/s, while it bobs up and down
    # (vertical motion is not sliding).
    p[:, 2, 0], p[:, 2, 2], p[:, 2, 1] = 0.06 * t, 0.08 * t, 0.05 * np.sin(7 * t)
    # Right foot (joint 3): 10 cm/s along -x while in contact; fast swing (2 m/s) while not.
    swing = np.zeros(T, bool)
    swing[15:25] = True
    v = np.where(swing, 2.0, 0.10) / FPS
    p[:, 3, 0] = -np.concatenate([[0.0], np.cumsum(v[1:])])
    contacts = np.ones((T, 2), bool)
    contacts[15:24, 1] = False  # frames 15..24 move at 2 m/s; 24 -> 25 and later are in contact again
    contacts[24, 1] = False
    speeds = metrics.foot_contact_speeds(p, contacts, (2, 3), FPS)
    assert speeds.shape == ((T - 1) + (T - 1 - 11),)  # the right foot loses the pairs touching 15..24
    np.testing.assert_allclose(speeds, 10.0, rtol=1e-9)
    assert metrics.foot_sliding(p, contacts, (2, 3), FPS) == pytest.approx(10.0, rel=1e-9)
    assert metrics.foot_sliding_p95(p, contacts, (2, 3), FPS) == pytest.approx(10.0, rel=1e-9)
    # The summary of these samples (how eval pools them) says the same.
    out = metrics._summary({"sliding": [speeds], "sliding_ik_off": [speeds]}, 0, T - 1, FPS)
    for key in ("foot_sliding_cm_per_s", "foot_sliding_p95_cm_per_s", "foot_sliding_ik_off_cm_per_s",
                "foot_sliding_ik_off_p95_cm_per_s"):
        assert out[key] == pytest.approx(10.0, rel=1e-9)


def test_foot_sliding_pools_samples_over_recordings():
    # Two recordings: mean and p95 of the pooled samples, not the mean of per-recording means.
    rng = np.random.default_rng(0)
    recs, all_speeds = [], []
    for T in (12, 30):
        p = np.cumsum(rng.normal(0, 0.01, (T, 4, 3)), axis=0)
        c = rng.random((T, 2)) < 0.7
        recs.append(dict(positions=p, contacts=c))
        all_speeds.append(metrics.foot_contact_speeds(p, c, (2, 3), FPS))
    s = np.concatenate(all_speeds)
    pooled = {"sliding": list(all_speeds)}
    out = metrics._summary(pooled, 0, 0, FPS)
    assert out["foot_sliding_cm_per_s"] == pytest.approx(s.mean())
    assert out["foot_sliding_p95_cm_per_s"] == pytest.approx(np.percentile(s, 95))


def _straight_controller(db, ik: bool, start: int, steps: int):
    """A Character fed the database's own trajectory features: each query equals the current
    frame's features, so the continuation (cost 0) always wins: the clip played straight."""
    from mmrl.character import Character

    c = Character(db, ik=ik, foot_locking=ik, record=True, start_frame=start, action_limit_std=None)  # no clipping
    for _ in range(steps):
        c.step(db.normalized_features[c.frame, 15:].copy())
    return c.recording()


def _a_long_clip(db):
    lengths = np.diff(db.clip_ranges, axis=1)[:, 0]
    clip = int(np.argmax(lengths))
    a, b = (int(v) for v in db.clip_ranges[clip])
    start = int(np.flatnonzero(db.valid_mask[a:b])[0]) + a
    steps = (b - 31 - start) // 6  # every decision's frame stays a valid match
    return start, steps


@pytest.fixture(scope="module")
def walk_db(shared_data):
    """Two real walks: feet that slide a few cm/s in contact (the synthetic data barely slides)."""
    return mmrl.Database.from_bvh(sorted((shared_data / "normal").glob("*_walk_*.bvh"))[:2])


def test_a_clip_played_straight_has_no_transition_no_excess_jump_and_the_raw_sliding(walk_db):
    db = walk_db
    start, steps = _a_long_clip(db)
    assert steps >= 10
    frames = np.arange(start, start + 6 * steps + 1)
    # Hand loop over the raw FK: the database's own ankles over these frames.
    g = _core.database_global_positions(db._db, frames.astype(np.int64)).astype(np.float64)
    speeds = []
    for side, j in enumerate(metrics.feet(db)):
        for t in range(1, len(frames)):
            if db.contacts[frames[t], side] and db.contacts[frames[t - 1], side]:
                d = g[t, j] - g[t - 1, j]
                speeds.append(100 * db.fps * np.hypot(d[0], d[2]))
    assert len(speeds) > 20 and np.mean(speeds) > 1.0
    for ik in (False, True):
        rec = _straight_controller(db, ik, start, steps)
        np.testing.assert_array_equal(rec["frames"], frames)
        q = metrics.quality(db, rec)
        assert q["transitions_per_s"] == 0.0 and q["matched_cost_mean"] == 0.0
        # float32 world positions (the character is placed elsewhere than the database's world): 1e-3.
        assert q["foot_sliding_ik_off_cm_per_s"] == pytest.approx(np.mean(speeds), rel=1e-3)
        assert q["foot_sliding_ik_off_p95_cm_per_s"] == pytest.approx(np.percentile(speeds, 95), rel=1e-3)
        if not ik:  # IK moves the ankles (locks): an excess of its own
            assert q["max_pose_jump_cm"] < 1e-3 and q["pose_jump_p99_cm"] < 1e-3
            assert q["foot_sliding_cm_per_s"] == q["foot_sliding_ik_off_cm_per_s"]


def test_animated_feet_are_the_ankles_of_the_same_run_with_ik_off():
    from mmrl.character import Character

    db = default_database()
    rng = np.random.default_rng(3)
    on = Character(db, record=True)
    off = Character(db, ik=False, foot_locking=False, record=True)
    for _ in range(40):
        q = db.normalized_features[rng.choice(np.flatnonzero(db.valid_mask)), 15:] + rng.normal(0, 0.3, 12)
        q = q.astype(np.float32)
        a, b = on.step(q), off.step(q)
        assert a.match == b.match
        np.testing.assert_array_equal(a.animated_feet, b.positions[:, metrics.feet(db)])
        np.testing.assert_array_equal(b.animated_feet, b.positions[:, metrics.feet(db)])
    ra = on.recording()
    np.testing.assert_array_equal(ra["animated_feet"], off.recording()["positions"][:, metrics.feet(db)])
    assert ra["costs"].shape == ra["transitions"].shape == (40,)


def test_eval_reports_sliding_with_ik_on_and_off_from_one_run():
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import evaluate_full_path

    db = default_database()
    task = mmrl.get_task("plane")
    pol = JoystickPolicy.preset(db, "joystick")
    on = evaluate_full_path(task, db, pol, episodes=4, seed=2)
    off = evaluate_full_path(task, db, pol, episodes=4, seed=2, ik=False, foot_locking=False)
    # The same episodes and decisions: the IK-off numbers of the IK run are the IK-off run's own.
    assert on["transitions_per_s"] == off["transitions_per_s"] and on["matched_cost_mean"] == off["matched_cost_mean"]
    assert on["foot_sliding_ik_off_cm_per_s"] == pytest.approx(off["foot_sliding_cm_per_s"], rel=1e-9)
    assert on["foot_sliding_ik_off_p95_cm_per_s"] == pytest.approx(off["foot_sliding_p95_cm_per_s"], rel=1e-9)
    assert off["foot_sliding_ik_off_cm_per_s"] == pytest.approx(off["foot_sliding_cm_per_s"], rel=1e-9)
    assert on["foot_sliding_cm_per_s"] < on["foot_sliding_ik_off_cm_per_s"]
    assert on["raw_mocap"] == {k: metrics.raw_mocap_floor(db)[k] for k in on["raw_mocap"]}
    assert set(on["raw_mocap"]) == {"foot_sliding_cm_per_s", "foot_sliding_p95_cm_per_s", "pose_jump_p99_cm"}
    # The matched cost is the mean of the decisions' own costs; jumps are p99 <= max.
    assert on["matched_cost_mean"] > 0 and on["pose_jump_p99_cm"] <= on["max_pose_jump_cm"]
    for e in on["episode_results"]:
        assert e["pose_jump_p99_cm"] <= e["max_pose_jump_cm"] <= on["max_pose_jump_cm"] + 1e-9


def test_raw_mocap_floor_equals_a_hand_loop():
    db = default_database()
    g = _core.database_global_positions(db._db, np.arange(db.num_frames, dtype=np.int64)).astype(np.float64)
    feet = metrics.feet(db)
    speeds = []
    for a, b in db.clip_ranges:
        for side, j in enumerate(feet):
            for t in range(a + 1, b):
                if db.contacts[t, side] and db.contacts[t - 1, side]:
                    d = g[t, j] - g[t - 1, j]
                    speeds.append(100 * db.fps * np.hypot(d[0], d[2]))
    floor = metrics.raw_mocap_floor(db)
    assert floor["frames"] == db.num_frames
    assert floor["foot_sliding_cm_per_s"] == pytest.approx(np.mean(speeds), rel=1e-9)
    assert floor["foot_sliding_p95_cm_per_s"] == pytest.approx(np.percentile(speeds, 95), rel=1e-9)
    assert floor["pose_jump_p99_cm"] == 0.0  # a clip played straight is its own reference
    # Chunking does not change the result (clips are never split).
    old = metrics._FLOOR_CHUNK_FRAMES
    try:
        metrics._FLOOR_CHUNK_FRAMES = 50
        metrics._FLOOR_CACHE.clear()
        assert metrics.raw_mocap_floor(db) == pytest.approx(floor)
    finally:
        metrics._FLOOR_CHUNK_FRAMES = old
        metrics._FLOOR_CACHE.clear()


def test_metric_functions_refuse_bad_input_naming_the_argument():
    db = default_database()
    T = 6
    p = np.zeros((T, 4, 3))
    c = np.ones((T, 2), bool)
    with pytest.raises(ValueError, match="positions"):
        metrics.foot_sliding(p[:, :, :2], c, (2, 3), FPS)
    with pytest.raises(ValueError, match="positions"):
        metrics.foot_sliding(p[0], c, (2, 3), FPS)
    bad = p.copy()
    bad[2, 3, 0] = np.nan
    with pytest.raises(ValueError, match="positions.*NaN"):
        metrics.foot_sliding(bad, c, (2, 3), FPS)
    with pytest.raises(ValueError, match="contacts"):
        metrics.foot_sliding(p, c[:-1], (2, 3), FPS)
    with pytest.raises(ValueError, match="contacts"):
        metrics.foot_sliding_p95(p, c[:, :1], (2, 3), FPS)
    with pytest.raises(ValueError, match="foot_joints"):
        metrics.foot_sliding(p, c, (2, 4), FPS)
    with pytest.raises(ValueError, match="fps"):
        metrics.foot_sliding(p, c, (2, 3), 0.0)
    J = db.num_joints
    pj = np.zeros((T, J, 3))
    roots = np.zeros((T, 3))
    frames = np.arange(T, dtype=np.int64)
    with pytest.raises(ValueError, match="positions"):
        metrics.pose_jumps(pj[:, :, :2], roots, frames, db)
    with pytest.raises(ValueError, match="positions.*NaN"):
        metrics.pose_jumps(np.full((T, J, 3), np.nan), roots, frames, db)
    with pytest.raises(ValueError, match="roots.*NaN"):
        metrics.pose_jumps(pj, np.full((T, 3), np.inf), frames, db)
    with pytest.raises(ValueError, match="frames"):
        metrics.pose_jumps(pj, roots, frames[:-1], db)
    with pytest.raises(ValueError, match="frames"):
        metrics.pose_jumps(pj, roots, frames + db.num_frames, db)
    with pytest.raises(ValueError, match="transitions"):
        metrics.transitions_per_second(np.zeros((3, 2), bool), 6, FPS)
    with pytest.raises(ValueError, match="recording"):
        metrics.quality(db, {"positions": pj})
    rec = {"positions": pj, "roots": roots, "frames": frames, "contacts": c[:-2], "transitions": np.zeros(1, bool)}
    with pytest.raises(ValueError, match="contacts"):
        metrics.quality(db, rec)
