"""Motion while standing (issue 38, mmrl.eval.standing): the raw-mocap floor over a subset of
frames against the floor of a database of that subset alone, the idle frames against the motion
kinds, the standing phase's segment and stop jump against brute force over the recording, the
same episodes for every controller, the arrive task's stand step by step, and the stand's
preference for frames that go on standing against brute force on two skeletons."""
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
from test_candidate_filter import brute_force_decision
from test_import_axes_fps import other_skeleton_database

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


def _stand_query(db, st) -> np.ndarray:
    """The stand by hand: every trajectory sample at the target, facing the target facing, in
    the character frame (x left, z forward), normalized as the database normalizes features."""
    d = st["facing"] - st["yaw"]
    dx, dz = st["target"][0] - st["x"], st["target"][1] - st["z"]
    c, s = math.cos(st["yaw"]), math.sin(st["yaw"])
    goal = [c * dx - s * dz, s * dx + c * dz]  # forward is (sin yaw, cos yaw), left (cos yaw, -sin yaw)
    raw = np.zeros(27)
    for k in range(3):
        p = mmrl._core.TRAJECTORY_POSITION_COLUMNS[k]
        raw[p:p + 4] = [goal[0], goal[1], math.sin(d), math.cos(d)]
    return db.normalize(raw)[15:]


@pytest.mark.parametrize("stand_exit", [1.0, 2.0])
def test_the_match_asks_for_a_stand_within_stand_radius_and_the_facing_tolerance(stand_exit):
    """Step by step against an env with stand_radius 0 driven by the same actions, except that
    within stand_radius and facing_tolerance (by hand), or once arrived (a decision at rest, the
    shown frame's hips slower than stop_speed, within success_radius and facing_tolerance) within
    stand_exit times those, it gets the stand by hand: the same matches, roots and rewards for
    900 steps."""
    db = mmrl.default_database()
    features = np.asarray(db.features)
    config = ARRIVE.default_config().replace(success_radius=0.5, stand_radius=0.3, facing_tolerance=0.5,
                                             target_half_extent=2.0, min_target_distance=0.8, hold_time=3.0,
                                             stand_exit=stand_exit, stand_idle_cost=0.0,
                                             stand_anchor=False)  # its root move: the test of planted feet below
    standing = ARRIVE.make_vector_env(1, db=db, config=config, num_threads=1)
    plain = ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_radius=0.0), num_threads=1)
    obs, _ = standing.reset(seed=2)
    plain.reset(seed=2)
    policy = JoystickPolicy(db, database_speeds(db)[0], arrive=True)
    policy.bind_layout(standing.observation_layout)
    rng = np.random.default_rng(0)
    stands = held = wide = 0
    arrived = False

    def within(st, radius, tolerance):
        return (math.hypot(st["target"][0] - st["x"], st["target"][1] - st["z"]) <= radius
                and abs((st["facing"] - st["yaw"] + math.pi) % (2 * math.pi) - math.pi) <= tolerance)

    for _ in range(900):
        st = standing.env_state(0)
        if arrived:
            arrived = within(st, stand_exit * config.success_radius, stand_exit * config.facing_tolerance)
        elif within(st, config.success_radius, config.facing_tolerance):
            hips = features[st["frame"]]  # features.hpp: [12:15] the hips velocity
            arrived = math.hypot(hips[12], hips[14]) < config.stop_speed
        near = within(st, config.stand_radius, config.facing_tolerance)
        stand = arrived or near
        stands += stand
        held += arrived and not near
        wide += arrived and not within(st, config.success_radius, config.facing_tolerance)
        action = rng.normal(0, 1, (1, 12)).astype(np.float32) if rng.random() < 0.5 else policy.act(obs)
        obs, r1, terminated, truncated, _ = standing.step(action)
        _, r0, *_ = plain.step(_stand_query(db, st)[None].astype(np.float32) if stand else action)
        a, b = standing.env_state(0), plain.env_state(0)
        assert a["last_step_match"] == b["last_step_match"]
        assert (a["x"], a["z"], a["yaw"]) == pytest.approx((b["x"], b["z"], b["yaw"]), abs=1e-5)
        assert r1[0] == pytest.approx(r0[0], abs=1e-5)
        if terminated[0] or truncated[0]:
            arrived = False  # a new episode has not arrived
    assert stands >= 10 and held >= 3  # the stand and the arrival mattered (not vacuous)


@pytest.mark.parametrize("stand_exit", [1.0, 2.0])
def test_an_arrived_character_keeps_standing_within_stand_exit(stand_exit):
    """A character at rest 0.2 m from its target (within success_radius 0.3, outside stand_radius
    0.1) stands. With the target moved to 0.5 m (beyond success_radius, within 2x) it stands on
    with stand_exit 2 and follows the action with 1; at 0.7 m it follows the action with either."""
    db = mmrl.default_database()
    features = np.asarray(db.features)
    valid = np.asarray(db.valid_mask, bool)
    still = np.flatnonzero(valid & (np.hypot(features[:, 12], features[:, 14]) < 0.05))
    assert len(still) > 0
    config = ARRIVE.default_config().replace(success_radius=0.3, stand_radius=0.1, facing_tolerance=0.5,
                                             stand_exit=stand_exit, stand_idle_cost=0.0)
    env = ARRIVE.make_vector_env(1, db=db, config=config, num_threads=1)
    plain = ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_radius=0.0), num_threads=1)
    other = ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_radius=0.0), num_threads=1)
    for e in (env, plain, other):
        e.reset(seed=0)
    walk = np.tile(np.float32([0.0, 1.0, 0.0, 1.0]), 3) * np.float32([1, 1, 1, 1, 2, 2, 1, 1, 3, 3, 1, 1])
    walk = db.normalize(np.concatenate([np.zeros(15, np.float32), walk]))[15:][None].astype(np.float32)

    def decide(distance, expect_stand):
        st = env.env_state(0)
        for e in (env, plain, other):  # the target `distance` ahead, facing the character's way
            e.set_state(0, st["frame"], st["x"], st["z"], st["yaw"])
            # The runtime sets the facing before every decision: the same facing keeps the arrival.
            e.set_facing(0, st["facing"] if e is env else st["yaw"])
            e.set_target(0, st["x"] + distance * math.sin(st["yaw"]), st["z"] + distance * math.cos(st["yaw"]))
        st = env.env_state(0)
        stand = _stand_query(db, st)[None].astype(np.float32)
        env.step(walk)
        plain.step(stand if expect_stand else walk)
        other.step(walk if expect_stand else stand)  # the other choice: a different match
        assert env.env_state(0)["last_step_match"] == plain.env_state(0)["last_step_match"]
        assert env.env_state(0)["last_step_match"] != other.env_state(0)["last_step_match"]

    env.set_state(0, int(still[0]), 0.0, 0.0, 0.0)
    env.set_facing(0, 0.0)
    decide(0.2, True)   # arrives: at rest within success_radius
    decide(0.5, stand_exit >= 2.0)
    if stand_exit >= 2.0:
        decide(0.7, False)


def stand_idle_costs(db, seconds, cost, still=False) -> np.ndarray:
    """Each frame's cost in a stand by hand (arrive.hpp's stand-idle rule): an idle frame (the
    motion kinds' measure) that goes on standing t seconds (its run of idle frames in its clip,
    to the last one's next second) costs cost * max(0, 1 - t / seconds); any other frame cost.
    ``still``: the same over the idle frames that also turn less than 20 degrees over their next
    second, for no longer than both feet stay planted (slower than 0.3 m/s; a run of such frames
    from this one on): what the rule prices once the facing is within 5 degrees."""
    idle = idle_frames(db)
    f = np.asarray(db.features, np.float64)
    planted = np.ones(db.num_frames, bool)
    if still:
        d = mmrl._core.TRAJECTORY_DIRECTION_COLUMNS[2]
        idle = idle & (np.degrees(np.abs(np.arctan2(f[:, d], f[:, d + 1]))) < 20.0)
        planted = (np.linalg.norm(f[:, 6:12].reshape(-1, 2, 3), axis=2) < 0.3).all(axis=1)
    out = np.full(db.num_frames, cost, np.float64)
    for a, b in np.asarray(db.clip_ranges):
        run = feet = 0
        for r in range(b - 1, a - 1, -1):
            run = run + 1 if idle[r] else 0
            feet = feet + 1 if planted[r] else 0
            if idle[r]:
                t = (run - 1 + 30) / db.fps
                if still:
                    t = min(t, feet / db.fps)
                out[r] = cost * max(0.0, 1.0 - t / seconds)
    return out


@pytest.mark.parametrize("turn", [0.1, 0.05])
@pytest.mark.parametrize("which, seconds", [("synthetic", 10.0), ("mixamo", 10.0), ("synthetic", 1.5)])
def test_a_standing_match_prefers_frames_that_go_on_standing(which, seconds, turn, tmp_path):
    """An arrived character (at rest at its target, `turn` radians short of its facing) on each
    of 40 still frames: its match is the brute-force decision with every frame's stand-idle cost
    added (and without it when the rule is off); the rule changes some matches and makes every
    changed one stand longer. 0.1 rad (5.7 degrees) is farther than the rule's 5 degrees, so idle
    frames that turn in place count as standing; 0.05 rad is within, so only still ones do, and only
    while both feet stay planted (the synthetic 1.5 s case fails without that part). With
    1.5 s the long runs' frames cost nothing and the last 0.5 s of each run costs, so a run length
    one frame off moves frames across that edge."""
    db = (mmrl.default_database() if which == "synthetic" else
          other_skeleton_database(tmp_path, clips=((1.4, 0.3), (0.0, 0.0), (1.2, -0.5), (3.0, 0.2))))
    features = np.asarray(db.features)
    still = np.flatnonzero(np.asarray(db.valid_mask, bool) & (np.hypot(features[:, 12], features[:, 14]) < 0.05))
    assert len(still) >= 40
    config = ARRIVE.default_config().replace(success_radius=0.3, stand_radius=0.1, facing_tolerance=0.5,
                                             hold_time=5.0, transition_cost=2.0, stand_idle_seconds=seconds,
                                             stand_idle_cost=20.0)
    envs = {cost: ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_idle_cost=cost), num_threads=1)
            for cost in (20.0, 0.0)}
    row_costs = {cost: stand_idle_costs(db, seconds, cost, still=turn < math.radians(5)) for cost in envs}
    low, high = envs[0.0].single_action_space.low, envs[0.0].single_action_space.high
    rng = np.random.default_rng(1)
    walk = rng.normal(0, 1, (1, 12)).astype(np.float32)  # the stand overrides it
    checked = changed = 0
    for frame in rng.choice(still, 40, replace=False):
        yaw = float(rng.uniform(-math.pi, math.pi))
        matches = {}
        for cost, env in envs.items():
            env.reset(seed=0)
            env.set_state(0, int(frame), 1.0, 2.0, yaw)
            env.set_facing(0, yaw + turn)
            env.set_target(0, 1.0 + 0.05 * math.sin(yaw), 2.0 + 0.05 * math.cos(yaw))
            query = _stand_query(db, env.env_state(0))
            env.step(walk)
            matches[cost] = env.env_state(0)["last_step_match"]
            want, _, slack = brute_force_decision(db, int(frame), query, low, high, config.transition_cost,
                                                  np.zeros(db.num_clips), row_costs[cost])
            if slack < 1e-3:  # float32 in C++ against float64 here: skip near-ties
                continue
            assert matches[cost] == want
            checked += 1
        if matches[20.0] != matches[0.0]:
            changed += 1
            assert row_costs[20.0][matches[20.0]] <= row_costs[20.0][matches[0.0]] + 1e-6
    assert checked >= 40 and changed >= (3 if seconds > 5 else 1)


def test_the_stand_idle_rule_waits_for_the_arrival():
    """Within stand_radius but not yet arrived (still moving, or outside success_radius) the
    stand asks for its query and the rule stays off: the same matches as with the rule off, step
    by step up to the first arrival, over several stand decisions."""
    db = mmrl.default_database()
    features = np.asarray(db.features)
    config = ARRIVE.default_config().replace(success_radius=0.15, stand_radius=0.6, facing_tolerance=0.6,
                                             target_half_extent=2.0, min_target_distance=1.0, hold_time=3.0)
    assert config.stand_idle_cost > 0
    on = ARRIVE.make_vector_env(1, db=db, config=config, num_threads=1)
    off = ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_idle_cost=0.0), num_threads=1)
    policy = JoystickPolicy(db, database_speeds(db)[0], arrive=True)
    policy.bind_layout(on.observation_layout)
    compared = stood = 0
    for seed in range(6):
        obs, _ = on.reset(seed=seed)
        off.reset(seed=seed)
        for _ in range(150):
            st = on.env_state(0)
            dist = math.hypot(st["target"][0] - st["x"], st["target"][1] - st["z"])
            facing = abs((st["facing"] - st["yaw"] + math.pi) % (2 * math.pi) - math.pi)
            hips = features[st["frame"]]
            if dist <= config.success_radius and facing <= config.facing_tolerance and \
                    math.hypot(hips[12], hips[14]) < config.stop_speed:
                break  # this decision arrives: the rule may price it
            stood += dist <= config.stand_radius and facing <= config.facing_tolerance
            action = policy.act(obs)
            obs, _, terminated, truncated, _ = on.step(action)
            off.step(action)
            assert on.env_state(0)["last_step_match"] == off.env_state(0)["last_step_match"]
            compared += 1
            if terminated[0] or truncated[0]:
                break
    assert compared >= 100 and stood >= 5, (compared, stood)


def _anchor_by_hand(db, shown, match, root, target, success_radius):
    """Decider::anchor and ArriveTask::keep_anchor in float64: with both feet slower than 0.3 m/s
    in both frames, minus their mean offset (x, z) from the frame shown to the match, unless that
    takes the root farther from the target than it is and than half the success radius."""
    f = np.asarray(db.features, np.float64)
    speeds = np.linalg.norm(f[[shown, match], 6:12].reshape(2, 2, 3), axis=2)
    if not (speeds < 0.3).all():
        return np.zeros(2)
    offset = (f[match, :6] - f[shown, :6]).reshape(2, 3)[:, [0, 2]].mean(0)
    anchor = -offset
    x, z, yaw = root
    moved = np.array([x + math.cos(yaw) * anchor[0] + math.sin(yaw) * anchor[1],
                      z - math.sin(yaw) * anchor[0] + math.cos(yaw) * anchor[1]])
    before = math.hypot(target[0] - x, target[1] - z)
    if np.hypot(*(np.asarray(target) - moved)) > max(before, 0.5 * success_radius):
        return np.zeros(2)
    return anchor


def _feet_path(character, first: int, match: int, root, anchor, steps: int = 3) -> float:
    """The horizontal path (m) of both animated ankles over up to `steps` decisions: the
    transition from `first` to `match` (with `anchor`), then its continuation."""
    character.reset(first, (root[0], root[1]), root[2])
    before = np.asarray(character._core.current_animated_feet(), np.float64)
    feet = []
    for k in range(steps):
        if k > 0 and not character.db.valid_mask[character.frame]:
            break  # the clip ends: the same frames with and without the anchor
        res = character.play(match if k == 0 else int(character.frame), 0.0, anchor=anchor if k == 0 else (0, 0))
        feet.append(np.asarray(res.animated_feet, np.float64))
    path = np.concatenate([before[None]] + feet)[:, :, [0, 2]]
    return float(np.linalg.norm(np.diff(path, axis=0), axis=2).sum())


@pytest.mark.parametrize("which", ["synthetic", "mixamo"])
def test_an_arrived_stand_keeps_both_planted_feet_where_they_stand(which, tmp_path):
    """An arrived character on still frames, with the transition cost 0 so that the stand
    transitions: the anchor (stand_anchor) never changes the decision; it is the feet's offset
    by hand; the env's root moves by it; and the full path's ankles, played with it, travel less
    over the transition's blend than without it (same decisions)."""
    db = (mmrl.default_database() if which == "synthetic" else
          other_skeleton_database(tmp_path, clips=((1.4, 0.3), (0.0, 0.0), (1.2, -0.5))))
    features = np.asarray(db.features)
    valid = np.asarray(db.valid_mask, bool)
    still = np.flatnonzero(valid & (np.hypot(features[:, 12], features[:, 14]) < 0.05))
    still = still[valid[np.minimum(still + 18, db.num_frames - 1)]]  # room for three decisions
    config = ARRIVE.default_config().replace(success_radius=0.3, stand_radius=0.1, facing_tolerance=0.5,
                                             hold_time=5.0, transition_cost=0.0, stand_idle_cost=0.0)
    assert config.stand_anchor  # the default
    envs = {on: ARRIVE.make_vector_env(1, db=db, config=config.replace(stand_anchor=on), num_threads=1)
            for on in (True, False)}
    character = mmrl.Character(db, frames_per_step=config.frames_per_step, record=False)
    rng = np.random.default_rng(2)
    walk = rng.normal(0, 1, (1, 12)).astype(np.float32)  # the stand overrides it
    anchored = 0
    with_anchor = without = 0.0
    for frame in rng.choice(still, min(60, len(still)), replace=False):
        yaw = float(rng.uniform(-math.pi, math.pi))
        target = (1.0 + 0.05 * math.sin(yaw), 2.0 + 0.05 * math.cos(yaw))
        after = {}
        for on, env in envs.items():
            env.reset(seed=0)
            env.set_state(0, int(frame), 1.0, 2.0, yaw)
            env.set_facing(0, yaw)
            env.set_target(0, *target)
            env.step(walk)
            st = env.env_state(0)
            after[on] = (env.last_step_decision(0)[0], np.array([st["x"], st["z"]]), env.last_step_anchor(0))
        (match, root_on, anchor), (match_off, root_off, none) = after[True], after[False]
        assert match == match_off and none == (0.0, 0.0)
        want = _anchor_by_hand(db, int(frame), match, (1.0, 2.0, yaw), target, config.success_radius)
        np.testing.assert_allclose(anchor, want, atol=1e-5)
        shift = np.array([math.cos(yaw) * anchor[0] + math.sin(yaw) * anchor[1],
                          -math.sin(yaw) * anchor[0] + math.cos(yaw) * anchor[1]])
        np.testing.assert_allclose(root_on - root_off, shift, atol=1e-5)
        if anchor != (0.0, 0.0):
            anchored += 1
            with_anchor += _feet_path(character, int(frame), match, (1.0, 2.0, yaw), anchor)
            without += _feet_path(character, int(frame), match, (1.0, 2.0, yaw), (0.0, 0.0))
    assert anchored >= 10, anchored
    assert with_anchor < 0.8 * without, (with_anchor, without)


def test_an_anchor_that_is_not_two_finite_floats_is_refused():
    """Character.play / play_rows take an anchor of two finite floats; anything else is one
    ValueError naming it, and the character is unchanged."""
    db = mmrl.default_database()
    character = mmrl.Character(db, record=False)
    start = int(np.flatnonzero(np.asarray(db.valid_mask, bool))[0])
    character.reset(start)
    for bad in ((math.nan, 0.0), (0.0, math.inf), (1.0, 2.0, 3.0)):
        with pytest.raises(ValueError, match="anchor"):
            character.play(start, 0.0, anchor=bad)
        assert character.frame == start
    with pytest.raises(ValueError, match="anchor"):
        character._core.play(start, 0.0, (math.nan, 0.0))  # the binding checks too
