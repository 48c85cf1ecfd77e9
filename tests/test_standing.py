"""Motion while standing (issue 38, mmrl.eval.standing): the raw-mocap floor over a subset of
frames against the floor of a database of that subset alone, the idle frames against the motion
kinds, the standing phase's segment and stop jump against brute force over the recording, the
same episodes for every controller, and the arrive task's rest transition cost step by step."""
import math

import numpy as np
import pytest

import mmrl
from mmrl import metrics
from mmrl.eval.standing import _segment, evaluate_standing, raw_idle_floor, stop_pose_jump
from mmrl.motion import synth
from mmrl.motion.kinds import idle_frames, motion_kinds
from mmrl.rl.policies import JoystickPolicy, database_speeds
from mmrl.rollout import FullPath

ARRIVE = mmrl.get_task("arrive")


def test_the_floor_over_one_clips_frames_is_that_clips_own_floor():
    files = sorted(synth.default_dataset_dir().glob("synth_*.bvh"))[:6]
    db = mmrl.Database.from_bvh(files)
    full = metrics.raw_mocap_floor(db)
    every = metrics.raw_mocap_floor(db, only=np.ones(db.num_frames, bool))
    for key in ("foot_sliding_cm_per_s", "foot_sliding_p95_cm_per_s", "pose_jump_p99_cm"):
        assert every[key] == pytest.approx(full[key], rel=1e-9, abs=1e-12)
    assert every["frames"] == db.num_frames - len(db.clip_ranges)  # every pair inside a clip
    none = metrics.raw_mocap_floor(db, only=np.zeros(db.num_frames, bool))
    assert none["frames"] == 0 and none["foot_sliding_cm_per_s"] == 0.0
    a, b = np.asarray(db.clip_ranges)[2]
    only = np.zeros(db.num_frames, bool)
    only[a:b] = True
    alone = metrics.raw_mocap_floor(mmrl.Database.from_bvh([files[2]]))
    sub = metrics.raw_mocap_floor(db, only=only)
    assert sub["frames"] == b - a - 1
    assert sub["foot_sliding_cm_per_s"] == pytest.approx(alone["foot_sliding_cm_per_s"], rel=1e-6)
    with pytest.raises(ValueError, match="only: expected"):
        metrics.raw_mocap_floor(db, only=np.ones(3, bool))


def test_idle_frames_are_the_motion_kinds_idle_share():
    db = mmrl.default_database()
    idle = idle_frames(db)
    assert idle.shape == (db.num_frames,) and not idle[~np.asarray(db.valid_mask)].any()
    assert idle[db.valid_mask].mean() == pytest.approx(motion_kinds(db)["idle"], abs=1e-12)
    floor = raw_idle_floor(db)
    assert 0 < floor["frames"] < idle.sum()  # pairs of two idle frames inside a clip


def test_a_standing_segment_and_its_stop_jump_against_the_recording():
    db = mmrl.default_database()
    fp = FullPath(ARRIVE, db, seed=0, continuous=True)
    rng = np.random.default_rng(0)
    for _ in range(7):
        fp.step(rng.normal(0, 1, 12).astype(np.float32))
    rec = fp.recording()
    F = fp.config.frames_per_step
    seg = _segment(rec, 3, F)
    assert seg["frames"].shape[0] == rec["frames"].shape[0] - 3 * F  # steps 3..6 and the frame before them
    np.testing.assert_array_equal(seg["positions"][0], rec["positions"][3 * F])
    np.testing.assert_array_equal(seg["transitions"], rec["transitions"][3:])
    q = metrics.QualityAccumulator.samples_of(db, seg)
    assert q["frames"] == 4 * F and q["transitions"] == int(rec["transitions"][3:].sum())
    jumps = metrics.pose_jumps(rec["positions"], rec["roots"], rec["frames"], db)  # jumps[t - 1]: frames t - 1, t
    stop = 17
    expected = jumps[stop - F - 1:stop + F].max()  # every pair within F frames of the stop
    assert stop_pose_jump(db, rec, stop, F) == pytest.approx(expected, rel=1e-9)


def test_standing_runs_the_same_episodes_for_every_controller_and_reports_against_raw_idle():
    db = mmrl.default_database()
    config = ARRIVE.default_config().replace(success_radius=1.5, stop_speed=1.0, facing_tolerance=1.2, hold_time=0.2,
                                             target_half_extent=2.5, min_target_distance=1.6, max_steps=60)
    speeds = database_speeds(db)
    a = evaluate_standing(ARRIVE, db, JoystickPolicy(db, speeds[0], arrive=True), episodes=4, seconds=1.0,
                          config=config, seed=5)
    b = evaluate_standing(ARRIVE, db, JoystickPolicy(db, speeds[-1], arrive=True), episodes=4, seconds=1.0,
                          config=config, seed=5)
    assert [e["target"] for e in a["episode_results"]] == [e["target"] for e in b["episode_results"]]
    assert [e["facing"] for e in a["episode_results"]] == [e["facing"] for e in b["episode_results"]]
    assert a["stood"] == sum(e["success"] for e in a["episode_results"]) >= 1  # not vacuous
    assert a["seconds"] == pytest.approx(1.0, abs=0.2)
    assert a["raw_idle"] == {k: raw_idle_floor(db)[k] for k in ("foot_sliding_cm_per_s", "frames")}
    for key in ("foot_sliding_cm_per_s", "foot_sliding_ik_off_cm_per_s", "transitions_per_s", "pose_jump_p99_cm",
                "stop_pose_jump_median_cm", "moved_cm"):
        assert a[key] is not None and math.isfinite(a[key]) and a[key] >= 0
    with pytest.raises(ValueError, match="does not end at rest"):
        evaluate_standing(mmrl.get_task("plane"), db, JoystickPolicy(db, speeds[0]), episodes=1)
    with pytest.raises(ValueError, match="seconds must be positive"):
        evaluate_standing(ARRIVE, db, JoystickPolicy(db, speeds[0]), episodes=1, seconds=0)


def _stands_and_within(db, st, config) -> bool:
    """The rest rules by hand: (within the tolerances while the frame shown moves less than
    0.15 m over its next second (its raw +30-frame trajectory sample), within the tolerances)."""
    d = math.hypot(st["target"][0] - st["x"], st["target"][1] - st["z"])
    e = abs((st["facing"] - st["yaw"] + math.pi) % (2 * math.pi) - math.pi)
    p = mmrl._core.TRAJECTORY_POSITION_COLUMNS[2]
    f = np.asarray(db.features)[st["frame"]]
    within = d <= config.success_radius and e <= config.facing_tolerance
    return within and math.hypot(f[p], f[p + 1]) < 0.15, within


def test_the_rest_rules_price_each_decision_made_standing_within_the_tolerances():
    """Every step: the transition cost the env's decision used is transition_cost, plus
    rest_transition_cost when, as the step began, the character was within success_radius and
    facing_tolerance of the goal and its frame stood (the rule by hand); and the reward of an
    env with rest_transition_penalty is the reward without it minus the penalty for each
    transition decided within the tolerances, on the same actions (the penalty changes no motion)."""
    db = mmrl.default_database()
    config = ARRIVE.default_config().replace(success_radius=1.0, facing_tolerance=1.5, transition_cost=3.0,
                                             rest_transition_cost=40.0, target_half_extent=2.0,
                                             min_target_distance=0.8, hold_time=2.0)
    env = ARRIVE.make_vector_env(1, db=db, config=config, num_threads=1)
    plain = ARRIVE.make_vector_env(1, db=db, config=config.replace(rest_transition_penalty=0.0), num_threads=1)
    penalized = ARRIVE.make_vector_env(1, db=db, config=config.replace(rest_transition_penalty=0.7), num_threads=1)
    obs, _ = env.reset(seed=2)
    for e in (plain, penalized):
        e.reset(seed=2)
    policy = JoystickPolicy(db, database_speeds(db)[0], arrive=True)
    policy.bind_layout(env.observation_layout)
    rng = np.random.default_rng(0)
    rests = penalties = 0
    transitions, costs = np.zeros(1, np.uint8), np.zeros(1, np.float32)
    for _ in range(300):
        at_rest, within = _stands_and_within(db, env.env_state(0), config)
        rests += at_rest
        action = policy.act(obs) if rng.random() < 0.8 else rng.normal(0, 1, (1, 12)).astype(np.float32)
        obs, _, term, trunc, _ = env.step(action)
        assert env.env_state(0)["last_step_transition_cost"] == pytest.approx(3.0 + (40.0 if at_rest else 0.0))
        _, r0, *_ = plain.step(action)
        _, r1, *_ = penalized.step(action)
        plain._core.last_step_transitions(transitions, costs)
        penalty = 0.7 if within and transitions[0] else 0.0
        penalties += penalty > 0
        assert r1[0] == pytest.approx(r0[0] - penalty, abs=1e-5)
    assert rests >= 5 and penalties >= 1  # not vacuous
