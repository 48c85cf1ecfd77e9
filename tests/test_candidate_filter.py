"""The decision's candidate filter (kdtree.hpp's CandidateFilter), through its first rule: the
task option ``clip_costs`` (decision.hpp's ClipCostFilter), written once in C++.

A numpy brute force with the same rule checks the env's decisions; the full path plays the
env's decisions (it never decides again); the engine runtime reads the costs from the
controller file and agrees with the full path decision for decision; ``mmrl play``'s live
loop honours it. On the synthetic skeleton and on a second one (Mixamo names, other channel
orders)."""
import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.motion.clip_costs import clip_cost_array
from mmrl.rl.policies import JoystickPolicy
from mmrl.rollout import FullPath
from mmrl.export.runtime_export import read_controller, write_controller
from mmrl.tasks.plane import PlaneConfig, PlaneVectorEnv
from runtime_helpers import drive_both
from test_import_axes_fps import other_skeleton_database
from test_runtime import random_plane_policy


@pytest.fixture(scope="module")
def db():
    return mmrl.default_database()


@pytest.fixture(scope="module")
def mixamo_db(tmp_path_factory):
    return other_skeleton_database(tmp_path_factory.mktemp("mixamo"))


def brute_force_decision(db, frame, action, low, high, transition_cost, clip_costs, row_costs=None):
    """(frame to play from, its filtered cost, slack to the nearest competitor) by the rule of
    decision.hpp with a per-clip extra cost (and a per-frame one, row_costs)."""
    rows = np.asarray(db.normalized_features, np.float64)
    query = np.concatenate([rows[frame, :15], np.clip(action, low, high)])
    cost = ((rows - query) ** 2).sum(1) + np.asarray(clip_costs, np.float64)[db.frame_clip]
    if row_costs is not None:
        cost = cost + row_costs
    allowed = np.asarray(db.valid_mask, bool) & np.isfinite(cost)
    c = int(db.frame_clip[frame])
    start, stop = db.clip_ranges[c]
    allowed[max(start, frame - 20):min(stop, frame + 21)] = False
    order = np.flatnonzero(allowed)[np.argsort(cost[allowed], kind="stable")]
    best = int(order[0])
    slack = cost[order[1]] - cost[best] if order.size > 1 else np.inf
    if db.valid_mask[frame] and np.isfinite(cost[frame]):
        threshold = cost[frame] - transition_cost
        slack = min(slack, abs(cost[best] - threshold))
        if not cost[best] < threshold:
            return frame, cost[frame], slack
    return best, cost[best], slack


def busiest_clip(db, config, steps=150, seed=0):
    """The clip a joystick with noise plays most on ``db``: the one a test bans."""
    env = PlaneVectorEnv(8, db=db, config=config, num_threads=1)
    counts = np.zeros(db.num_clips, np.int64)
    for _, matches in run_env(env, steps, seed):
        np.add.at(counts, db.frame_clip[matches], 1)
    return int(np.argmax(counts)), counts


def run_env(env, steps, seed):
    """Steps ``env`` with noisy joystick actions; yields (frames before, matches) per step, with
    the (action, frame) of every env kept on env.trace for a brute-force check."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    joy = JoystickPolicy(env.db, layout=env.observation_layout)
    env.trace = []
    for _ in range(steps):
        frames = env.current_frames()
        actions = (joy.act(obs) + rng.normal(0, 0.8, (env.num_envs, 12))).astype(np.float32)
        obs, *_ = env.step(actions)
        matches = np.array([env.last_step_decision(i)[0] for i in range(env.num_envs)])
        costs = np.array([env.last_step_decision(i)[1] for i in range(env.num_envs)])
        env.trace.append((frames, actions, matches, costs))
        yield frames, matches


def clip_spec(db, clip, cost="inf"):
    return f"{db.clip_names[clip]}={cost}"


@pytest.mark.parametrize("which", ["synthetic", "mixamo"])
@pytest.mark.parametrize("cost", ["inf", "3.0"])
def test_env_decisions_follow_the_filtered_rule_by_brute_force(db, mixamo_db, which, cost):
    d = db if which == "synthetic" else mixamo_db
    base = PlaneConfig(transition_cost=1.0)
    clip, counts = busiest_clip(d, base)
    assert counts[clip] > 0
    config = base.replace(clip_costs=clip_spec(d, clip, cost))
    env = PlaneVectorEnv(8, db=d, config=config, num_threads=1)
    costs = clip_cost_array(config.clip_costs, d)
    # By name: a mirrored clip shares its source's name, so both get the cost.
    named = np.array([n == d.clip_names[clip] for n in d.clip_names])
    np.testing.assert_array_equal(costs, np.where(named, float(cost), 0.0).astype(np.float32))
    low, high = env.single_action_space.low, env.single_action_space.high
    for _ in run_env(env, 150, 0):
        pass
    checked = played = 0
    for frames, actions, matches, match_costs in env.trace:
        played += int(np.count_nonzero(named[d.frame_clip[matches]]))
        for i in range(env.num_envs):
            want, want_cost, slack = brute_force_decision(d, int(frames[i]), actions[i], low, high, 1.0, costs)
            if slack < 1e-3:  # float32 in C++ against float64 here: skip near-ties
                continue
            assert matches[i] == want
            assert match_costs[i] == pytest.approx(want_cost, rel=1e-4, abs=1e-4)
            checked += 1
    assert checked > 900
    if cost == "inf":
        assert played == 0  # the banned clip never plays
    else:
        assert played < counts[named].sum()  # a dearer clip plays less


def test_the_full_path_plays_the_env_decisions(db):
    """FullPath plays env.last_step_decision: with the filter, its shown frames are the env's
    matches' frames, the roots agree and no banned frame is shown, across episode ends."""
    base = PlaneConfig(transition_cost=1.0)
    clip, _ = busiest_clip(db, base)
    task = mmrl.get_task("plane")
    run = FullPath(task, db, config=base.replace(clip_costs=clip_spec(db, clip), max_steps=30), seed=3,
                   record=False)
    rng = np.random.default_rng(3)
    joy = JoystickPolicy(db, layout=run.env.observation_layout)
    ends = 0
    for _ in range(300):
        out = run.step((joy.act(run.obs[None]) + rng.normal(0, 0.8, (1, 12))).astype(np.float32)[0])
        match, _ = run.env.last_step_decision(0)
        assert out["res"].match == match
        np.testing.assert_array_equal(out["res"].frames, match + 1 + np.arange(6))
        assert not np.any(db.frame_clip[out["res"].frames] == clip)
        ends += out["done"]
        if not out["done"]:
            assert run.root_error() == (0, 0.0)
    assert ends >= 5


def test_runtime_reads_the_filter_and_agrees_with_the_full_path(db, tmp_path):
    base = PlaneConfig(transition_cost=1.0)
    # Without the section the policy plays some clip most: the filter below keeps that clip out.
    plain = tmp_path / "plain.mmrl"
    write_controller(plain, db, random_plane_policy(2), "plane", base)
    assert "task.clip_costs" not in read_controller(plain).sections
    free = drive_both(plain, mmrl.get_task("plane"), db, base, _core.RuntimeController.load(str(plain)).act, 400)
    clip = int(np.argmax(np.bincount(db.frame_clip[free["rt_matches"]], minlength=db.num_clips)))
    assert np.sum(db.frame_clip[free["rt_matches"]] == clip) >= 10
    config = base.replace(clip_costs=clip_spec(db, clip))
    path = tmp_path / "banned.mmrl"
    write_controller(path, db, random_plane_policy(2), "plane", config)
    back = read_controller(path)
    np.testing.assert_array_equal(back.sections["task.clip_costs"], clip_cost_array(config.clip_costs, db))
    c = _core.RuntimeController.load(str(path))
    out = drive_both(path, mmrl.get_task("plane"), back.db, config, c.act, 400)
    np.testing.assert_array_equal(out["rt_matches"], out["py_matches"])
    assert out["frame_mismatches"] == 0 and out["root_error"] <= 1e-5
    assert not np.any(db.frame_clip[out["rt_matches"]] == clip)


def test_mmrl_play_honours_the_filter(db):
    from mmrl.viewer.live import LiveSession

    task = mmrl.get_task("plane")
    base = task.default_config().replace(transition_cost=1.0)
    clip, _ = busiest_clip(db, base)
    s = LiveSession(task, db, JoystickPolicy.preset(db, "joystick"), config=base.replace(clip_costs=clip_spec(db, clip)))
    shown = []
    targets = np.random.default_rng(0).uniform(-4, 4, (20, 2))
    for k in range(20 * 30):
        if k % 30 == 0:
            s.set_target(*targets[k // 30])
        s.step()
        shown.append(s.run.character.frame)
    shown = np.array(shown[6:])  # the start frame is the session's, not a match
    assert len(set(shown)) > 50 and not np.any(db.frame_clip[shown] == clip)


def test_bad_specs_name_the_option(db, tmp_path):
    for spec, fragment in [("walk", "PATTERN=COST"), ("x=-1", "PATTERN=COST"), ("=3", "PATTERN=COST"),
                           ("no-such-clip*=inf", "matches no clip"), ("*=cheap", "PATTERN=COST")]:
        with pytest.raises(ValueError, match="clip_costs") as e:
            PlaneVectorEnv(2, db=db, clip_costs=spec)
        assert fragment in str(e.value)
    # Every clip banned: the decision falls back to the plain match instead of stopping.
    env = PlaneVectorEnv(2, db=db, clip_costs="*=inf", num_threads=1)
    ref = PlaneVectorEnv(2, db=db, num_threads=1)
    for e in (env, ref):
        e.reset(seed=1)
    a = np.zeros((2, 12), np.float32)
    for _ in range(20):
        env.step(a)
        ref.step(a)
        assert env.last_step_decision(0)[0] == ref.last_step_decision(0)[0]
    # A controller file whose costs are not one per clip, or negative, is refused with the reason.
    path = tmp_path / "c.mmrl"
    write_controller(path, db, random_plane_policy(0), "plane", PlaneConfig(clip_costs=clip_spec(db, 0)))
    sections = read_controller(path).sections
    from mmrl.export.runtime_file import write_sections

    for bad, fragment in [(np.zeros(db.num_clips + 1, np.float32), "task.clip_costs"),
                          (np.full(db.num_clips, -1.0, np.float32), "must be >= 0")]:
        write_sections(path, dict(sections, **{"task.clip_costs": bad}))
        with pytest.raises(ValueError, match=fragment):
            _core.RuntimeController.load(str(path))


def test_patterns_match_a_clip_by_its_name_file_name_or_stem(db):
    import os

    name = db.clip_names[3]
    stem = os.path.splitext(os.path.basename(name))[0]
    want = clip_cost_array(f"{name}=2", db)
    assert np.count_nonzero(want) >= 1
    for pattern in (os.path.basename(name), stem, f"*{stem[-6:]}"):
        got = clip_cost_array(f"{pattern}=2", db)
        assert np.all(got[want > 0] == 2.0), pattern
    both = clip_cost_array(f"{stem}=2;{stem}=inf", db)  # costs of patterns add up
    assert np.all(np.isinf(both[want > 0]))
