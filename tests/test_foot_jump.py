"""The foot-jump rule (task option ``foot_jump_limit``, rules.cpp's FootJumpRule): a match refuses
frames whose left or right foot stands farther than the limit from where the shown frame has it
(feature columns [0:3] and [3:6], meters in the character frame), and falls back to the plain
match when it refuses every frame.

A numpy brute force with the same rule checks the env's decisions on the synthetic skeleton and
on a second one (Mixamo names, other channel orders); the engine runtime reads the option from
the controller file and decides as the full path does; a limit that refuses every transition
leaves only continuations and fallbacks."""
import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.export.runtime_export import read_controller, write_controller
from mmrl.tasks.plane import PlaneConfig, PlaneVectorEnv
from runtime_helpers import drive_both
from test_candidate_filter import db, mixamo_db, run_env  # noqa: F401 (db, mixamo_db: its fixtures)
from test_runtime import random_plane_policy

TRANSITION_COST = 1.0


def foot_distance(db, frame):
    """(num_frames,) the larger of the two feet's distances (m) from frame ``frame``'s feet."""
    f = np.asarray(db.features, np.float64)
    left = np.linalg.norm(f[:, 0:3] - f[frame, 0:3], axis=1)
    right = np.linalg.norm(f[:, 3:6] - f[frame, 3:6], axis=1)
    return np.maximum(left, right)


def brute_force(db, frame, action, low, high, limit):
    """(frame to play from, its cost, whether every frame was refused) by decision.hpp's rule with
    the foot-jump rule on top, or None when the decision sits within float32 rounding of a tie or
    of the limit."""
    rows = np.asarray(db.normalized_features, np.float64)
    query = np.concatenate([rows[frame, :15], np.clip(action, low, high)])
    dist = ((rows - query) ** 2).sum(1)
    feet = foot_distance(db, frame)
    allowed = np.asarray(db.valid_mask, bool).copy()
    c = int(db.frame_clip[frame])
    start, stop = db.clip_ranges[c]
    allowed[max(start, frame - 20):min(stop, frame + 21)] = False
    ok = feet <= limit
    fallback = not (allowed & ok).any() and not (db.valid_mask[frame] and ok[frame])
    if fallback:
        ok[:] = True  # every frame refused: the plain match
    cost = np.where(ok, dist, np.inf)
    order = np.flatnonzero(allowed & ok)
    order = order[np.argsort(cost[order], kind="stable")]
    if order.size == 0:
        return None
    best = int(order[0])
    near_limit = np.abs(feet - limit) < 1e-4
    if near_limit[allowed & (dist <= cost[best] + 1e-3)].any():
        return None
    slack = cost[order[1]] - cost[best] if order.size > 1 else np.inf
    if db.valid_mask[frame] and np.isfinite(cost[frame]):
        threshold = cost[frame] - TRANSITION_COST
        slack = min(slack, abs(cost[best] - threshold))
        if not cost[best] < threshold:
            best = frame
    if slack < 1e-3:
        return None
    return best, cost[best], fallback


def typical_jump(db, config, seed=0):
    """The median foot distance (m) of the transitions a noisy joystick makes without the rule:
    a limit there refuses about half of them."""
    env = PlaneVectorEnv(8, db=db, config=config, num_threads=1)
    jumps = []
    for frames, matches in run_env(env, 60, seed):
        for f, m in zip(frames, matches):
            if m != f:  # a transition (a continuation plays on from the shown frame)
                jumps.append(foot_distance(db, int(f))[m])
    assert len(jumps) > 20
    return float(np.median(jumps))


@pytest.mark.parametrize("which", ["synthetic", "mixamo"])
def test_env_decisions_follow_the_rule_by_brute_force(db, mixamo_db, which):
    d = db if which == "synthetic" else mixamo_db
    base = PlaneConfig(transition_cost=TRANSITION_COST)
    limit = typical_jump(d, base)
    env = PlaneVectorEnv(8, db=d, config=base.replace(foot_jump_limit=limit), num_threads=1)
    low, high = env.single_action_space.low, env.single_action_space.high
    for _ in run_env(env, 150, 0):
        pass
    checked = jumps = 0
    for frames, actions, matches, costs in env.trace:
        for i in range(env.num_envs):
            f = int(frames[i])
            want = brute_force(d, f, actions[i], low, high, limit)
            if want is None:
                continue
            assert matches[i] == want[0]
            assert costs[i] == pytest.approx(want[1], rel=1e-4, abs=1e-4)
            if matches[i] != f and not want[2]:
                jumps = max(jumps, foot_distance(d, f)[matches[i]])
            checked += 1
    assert checked > 600
    assert 0 < jumps <= limit + 1e-4  # transitions happen, and none jumps farther than the limit


def test_the_rule_changes_decisions_and_a_tiny_limit_keeps_the_plain_fallback(db):
    base = PlaneConfig(transition_cost=TRANSITION_COST)
    limit = typical_jump(db, base)
    free = PlaneVectorEnv(8, db=db, config=base, num_threads=1)
    ruled = PlaneVectorEnv(8, db=db, config=base.replace(foot_jump_limit=limit), num_threads=1)
    far = {}
    for env in (free, ruled):
        for _ in run_env(env, 60, 0):
            pass
        far[env] = sum(foot_distance(db, int(f))[m] > limit for frames, _, matches, _ in env.trace
                       for f, m in zip(frames, matches) if m != f)
    assert far[free] > 10 and far[ruled] == 0


def test_runtime_reads_the_limit_and_agrees_with_the_full_path(db, tmp_path):
    base = PlaneConfig(transition_cost=TRANSITION_COST)
    config = base.replace(foot_jump_limit=typical_jump(db, base))
    path = tmp_path / "feet.mmrl"
    write_controller(path, db, random_plane_policy(2), "plane", config)
    keys = list(read_controller(path).sections["task.keys"])
    assert "foot_jump_limit" in keys
    c = _core.RuntimeController.load(str(path))
    out = drive_both(path, mmrl.get_task("plane"), db, config, c.act, 300)
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5
    # Without it the same policy decides otherwise: the option is what the runtime honoured.
    plain = tmp_path / "plain.mmrl"
    write_controller(plain, db, random_plane_policy(2), "plane", base)
    free = drive_both(plain, mmrl.get_task("plane"), db, base, _core.RuntimeController.load(str(plain)).act, 300)
    assert not np.array_equal(free["rt_matches"], out["rt_matches"])


def test_a_negative_limit_is_refused_by_name(db):
    with pytest.raises(ValueError, match="foot_jump_limit"):
        PlaneVectorEnv(2, db=db, foot_jump_limit=-0.1)


def test_a_standalone_character_decides_with_the_rule(db):
    """mmrl.Character.step (no env) chains the same registered rules: its decisions equal the
    brute force, and the limit changes them."""
    from mmrl.rl.policies import JoystickPolicy

    limit = typical_jump(db, PlaneConfig(transition_cost=TRANSITION_COST))
    env = PlaneVectorEnv(1, db=db, config=PlaneConfig(), num_threads=1)
    low, high = env.single_action_space.low, env.single_action_space.high
    rng = np.random.default_rng(5)
    joy = JoystickPolicy(db, layout=mmrl.Character.observation_layout)
    characters = {lim: mmrl.Character(db, fast=True, transition_cost=TRANSITION_COST, foot_jump_limit=lim,
                                      start_frame=int(np.flatnonzero(db.valid_mask)[50])) for lim in (0.0, limit)}
    checked = differ = 0
    for _ in range(300):
        target = rng.uniform(-3, 3, 2)
        a = (joy.act(characters[limit].observation(target)[None])[0] + rng.normal(0, 0.8, 12)).astype(np.float32)
        frame = characters[limit].frame
        want = brute_force(db, frame, a, low, high, limit)
        res = characters[limit].step(a)
        free = characters[0.0]
        if free.frame == frame:  # the same state: the rule alone tells the two apart
            differ += free.step(a).match != res.match
        else:
            free.reset(frame, characters[limit].root[:2], characters[limit].root[2])
        if want is not None:
            assert res.match == want[0]
            checked += 1
    assert checked > 200 and differ > 0
    with pytest.raises(ValueError, match="foot_jump_limit"):
        mmrl.Character(db, foot_jump_limit=-1.0)
