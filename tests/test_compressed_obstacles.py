"""The collision-aware search for a compressed controller (issue 27; tasks/path_filter.hpp,
compressed.hpp's compressed_decision with a filter): a projection has no database path, so its
path is read from its own trajectory features (trajectory_path: the quadratic through the start
and the 10-, 20- and 30-frame positions), and its candidates are the projections of the query
and of the query's turned copies.

- the quadratic equals a database frame's own path where both are sampled (10, 20, 30 frames)
  and stays close in between;
- the env's path test of states equals a numpy reference (the quadratic placed at the root,
  the obstacles moved by the env's rule frame by frame);
- the env's compressed decisions equal a numpy brute force of the rule (every candidate's
  distance to the query plus its path cost, the continuation rule), and the filter and the fan
  change decisions (not vacuous).
On the synthetic skeleton and on a second one (Mixamo names, other channel orders)."""
import numpy as np
import pytest

import mmrl
from mmrl.compress.model import CompressedModel
from mmrl.rollout import apply_stage
from test_compress import small_compressed
from test_import_axes_fps import other_skeleton_database
from test_path_filter import (SAMPLES, config, moved_obstacles, nearest_obstacle, reference_first_hits, stepped,
                              turned_queries)

OFFSETS = np.array([0.0, 10.0, 20.0, 30.0])


@pytest.fixture(scope="module", params=["synthetic", "mixamo"])
def db(request, tmp_path_factory):
    if request.param == "synthetic":
        return mmrl.default_database()
    return other_skeleton_database(tmp_path_factory.mktemp("mixamo-cobst"))


@pytest.fixture(scope="module")
def controller(db, tmp_path_factory):
    return CompressedModel(small_compressed(db, tmp_path_factory.mktemp("cobst") / "c.pt"), db)


def raw_trajectory(db, features):
    scale = np.asarray(db.feature_scale, np.float64)[15:]
    mean = np.asarray(db.feature_mean, np.float64)[15:]
    return np.asarray(features, np.float64)[..., 15:] * scale + mean


def quadratic_paths(db, features):
    """(n, samples, 2): Lagrange quadratics through (0, p10, p20) before 10 frames, (p10, p20, p30) after."""
    raw = raw_trajectory(db, features).reshape(-1, 3, 4)
    pts = np.concatenate([np.zeros((raw.shape[0], 1, 2)), raw[:, :, :2]], 1)  # (n, 4, 2) at OFFSETS
    out = np.zeros((raw.shape[0], SAMPLES.size, 2))
    for s, f in enumerate(SAMPLES):
        a = 0 if f <= 10 else 1
        for m in range(a, a + 3):
            w = np.prod([(f - OFFSETS[o]) / (OFFSETS[m] - OFFSETS[o]) for o in range(a, a + 3) if o != m])
            out[:, s] += w * pts[:, m]
    return out


def reference_state_distances(db, state, obstacles, paths, cfg, moving):
    """(n, samples) distance from each path point, placed through the character's root, to the
    nearest obstacle where the env's motion rule puts it at that sample's frame."""
    dt = np.float32(1.0 / db.fps)
    half = np.float32(cfg.obstacle_square_half)
    c, s = np.cos(state["yaw"]), np.sin(state["yaw"])
    wx = state["x"] + c * paths[..., 0] + s * paths[..., 1]
    wz = state["z"] - s * paths[..., 0] + c * paths[..., 1]
    centres = obstacles["centres"].astype(np.float32).copy()
    v = obstacles["velocities"].astype(np.float32).copy()
    h, a = obstacles["half_sizes"], obstacles["angles"]
    out = []
    for t in range(1, SAMPLES[-1] + 1):
        if moving:
            centres, v = moved_obstacles(centres, v, dt, half)
        if t in SAMPLES:
            k = int(np.flatnonzero(SAMPLES == t)[0])
            out.append(nearest_obstacle(wx[:, k], wz[:, k], centres, h, a))
    return np.stack(out, axis=1)


def test_a_trajectory_s_path_is_the_frame_s_own_where_both_are_sampled(db):
    rows = np.flatnonzero(db.valid_mask)
    paths = quadratic_paths(db, np.asarray(db.normalized_features)[rows])
    truth = np.asarray(db.path_samples, np.float64)[rows]
    at = np.isin(SAMPLES, [10, 20, 30])
    np.testing.assert_allclose(paths[:, at], truth[:, at], atol=1e-4)
    between = np.hypot(*(paths[:, ~at] - truth[:, ~at]).transpose(2, 0, 1))
    assert between.mean() < 0.01 and np.percentile(between, 99) < 0.05, (between.mean(), between.max())


def test_the_state_path_test_equals_a_numpy_reference(db, controller):
    cfg = config()
    env = mmrl.get_task("obstacles").make_vector_env(4, db=db, config=cfg, num_threads=1)
    with pytest.raises(ValueError, match="no compressed controller"):
        env.state_path_hits(0, np.zeros((1, 27), np.float32))
    env._core.set_compressed(controller.core)
    apply_stage(mmrl.get_task("obstacles"), env, None)
    feats = np.asarray(db.normalized_features, np.float32)[np.flatnonzero(db.valid_mask)]
    rng = np.random.default_rng(4)
    radius = cfg.body_radius + cfg.path_margin
    reach = 6.0  # path_filter.hpp's kStateReach: farther points are pulled in
    scale = np.asarray(db.feature_scale, np.float64)[15:]
    mean = np.asarray(db.feature_mean, np.float64)[15:]
    checked = hits = mismatched = far = 0
    for _ in stepped(env, 20, 6):
        for i in range(env.num_envs):
            # Database frames' features and perturbed ones (what a projector may return).
            # and trajectories stretched past the reach, which the test pulls in.
            states = feats[rng.integers(0, feats.shape[0], 200)].copy()
            states[100:] += rng.normal(0, 0.3, (100, states.shape[1])).astype(np.float32)
            raw = raw_trajectory(db, states[180:])
            raw[:, [0, 1, 4, 5, 8, 9]] *= 6.0
            states[180:, 15:] = ((raw - mean) / scale).astype(np.float32)
            got = env.state_path_hits(i, states)
            paths = quadratic_paths(db, states)
            d = np.hypot(paths[..., 0], paths[..., 1])[..., None]
            far += int((d > reach).any(axis=(1, 2)).sum())
            paths = np.where(d > reach, paths * reach / np.maximum(d, 1e-9), paths)
            state = env.env_state(i)
            dist = reference_state_distances(db, state, env.obstacles(i), paths, cfg, state["max_speed"] > 0)
            want, near = reference_first_hits(dist, radius, cfg.path_horizon)
            keep = ~near
            mismatched += int((got != want)[keep].sum())
            checked += int(keep.sum())
            hits += int((want[keep] > 0).sum())
    assert mismatched == 0
    assert checked >= 5000 and 0.05 * checked < hits < 0.95 * checked, (checked, hits)
    assert far >= 500, far  # the pull-in was tested
    with pytest.raises(ValueError, match="features"):
        env.state_path_hits(0, np.zeros((2, 26), np.float32))
    with pytest.raises(ValueError, match="finite"):
        env.state_path_hits(0, np.full((1, 27), np.nan, np.float32))


def brute_force_compressed(model, db, state, action, low, high, path_cost, fan, fan_degrees, transition_cost=0.0):
    """(transition, chosen state, cost, slack, turned) by compressed_decision's rule with a filter."""
    query = np.concatenate([state[:15], np.clip(action, low, high)]).astype(np.float32)
    queries = np.asarray(turned_queries(db, query.astype(np.float64), fan, fan_degrees), np.float32)
    proj = model.project(queries)
    d = ((proj[:, :27].astype(np.float64) - query) ** 2).sum(1) + path_cost(proj[:, :27])
    stay = ((state[:27].astype(np.float64) - query) ** 2).sum() + path_cost(state[None, :27])[0]
    order = np.argsort(d, kind="stable")
    best = order[0]
    slack = min(abs(d[best] + transition_cost - stay), d[order[1]] - d[best] if d.size > 1 else np.inf)
    transition = d[best] + transition_cost < stay
    return transition, (proj[best] if transition else state), (d[best] if transition else stay), slack, best > 0


@pytest.mark.parametrize("fan", [0, 2])
def test_compressed_decisions_equal_a_brute_force_of_the_rule(db, controller, fan):
    cfg = config(compressed_path_fan=fan, path_fan_degrees=25.0)
    task = mmrl.get_task("obstacles")
    env = task.make_vector_env(4, db=db, config=cfg, num_threads=2)
    env._core.set_compressed(controller.core)
    apply_stage(task, env, None)
    low, high = env.single_action_space.low, env.single_action_space.high
    h = cfg.path_horizon
    compared = changed = turned = 0
    for _, actions in stepped(env, 60, 11):
        before = []
        for i in range(env.num_envs):
            def cost(features, i=i):
                first = env.state_path_hits(i, np.ascontiguousarray(features))
                return np.where(first > 0, cfg.path_cost * (2 - first / h), 0.0)

            state = env._core.compressed_state(i).copy()
            before.append((brute_force_compressed(controller.core, db, state, actions[i], low, high, cost, fan,
                                                  cfg.path_fan_degrees),
                           brute_force_compressed(controller.core, db, state, actions[i], low, high,
                                                  lambda f: np.zeros(len(f)), 0, 25.0)))
        env.step(actions)
        for i, ((t, chosen, want_cost, slack, by_turn), (plain_t, plain, _, _, _)) in enumerate(before):
            if slack < 1e-3:
                continue  # float rounding may order near-equal candidates either way
            # Turned queries are formed in float64 here, in float32 there: equal to rounding.
            np.testing.assert_allclose(env._core.compressed_chosen(i), chosen, rtol=0, atol=1e-4)
            assert env.last_step_decision(i)[1] == pytest.approx(want_cost, rel=1e-4, abs=1e-4)
            compared += 1
            changed += t != plain_t or not np.allclose(chosen, plain, rtol=0, atol=1e-4)
            turned += t and by_turn
    assert compared >= 120, compared
    assert changed >= 5, "the filter never changed a decision: the test tests nothing"
    if fan:
        assert turned >= 3, "no turned projection was ever chosen"


def test_the_runtime_plays_a_compressed_obstacles_controller_as_python_does(db, controller, tmp_path):
    """``mmrl export`` of an obstacles policy with a compressed controller: the C++ runtime, handed
    the env's moving obstacles before each decision, sees the same observation (sensor maps and the
    continuation's path test of the compressed state) and shows the same poses as Python's
    compressed full path, episode after episode from every start window."""
    from mmrl import _core
    from mmrl.export.compressed_export import WINDOW, write_compressed_controller
    from mmrl.export.runtime_file import read_sections
    from mmrl.rollout import FullPath
    from test_parity import hand_obstacles
    from test_runtime import random_obstacle_policy

    task = mmrl.get_task("obstacles")
    cfg = config(num_obstacles=40, max_steps=60)
    layout = task.make_vector_env(1, db=db, config=cfg, num_threads=1).layout
    path = tmp_path / "cobst.mmrl"
    write_compressed_controller(path, db, random_obstacle_policy(5, layout), task, cfg, controller, starts=4)
    rt = _core.RuntimeController.load(str(path))
    assert rt.compressed
    source = read_sections(path)["lmm.start_sources"]
    decisions = hits_seen = transitions = 0
    for episode in range(8):
        k = episode % 4
        fp = FullPath(task, db, config=cfg, seed=episode, record=False, compressed=controller)
        fp.env.set_state(0, int(source[k * WINDOW]), 0.0, 0.0, 0.0)
        fp._start_episode()
        fp.set_target(*fp.target)  # and the observation of the new start
        ch = _core.RuntimeCharacter(rt, *fp.character.root, k * WINDOW)
        ch.set_target(*fp.target)
        for _ in range(60):
            hand_obstacles(ch, fp.env)
            np.testing.assert_array_equal(ch.observe(), fp.obs)
            hits_seen += fp.obs[-2] > 0  # the compressed continuation's path test
            out = fp.step(rt.act(fp.obs))
            res = out["res"]
            for f in range(out["step_frames"]):
                ch.advance_frame()
                np.testing.assert_allclose(ch.root, res.roots[f], atol=1e-4)
                np.testing.assert_allclose(ch.global_positions(), res.positions[f], atol=1e-4)
            assert ch.last_decision()["transition"] == res.transition
            decisions += 1
            transitions += res.transition
            if out["done"]:
                break
    assert decisions >= 100 and transitions >= 10 and hits_seen >= 5, (decisions, transitions, hits_seen)


def test_the_live_view_draws_a_compressed_state_s_own_path(db, controller):
    """``mmrl play`` with a compressed obstacles controller draws the continuation's path from the
    compressed state (the quadratic of its trajectory, placed at the root) and its path test."""
    from mmrl import _core
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.viewer.live import LiveSession

    task = mmrl.get_task("obstacles")
    s = LiveSession(task, db, JoystickPolicy(db), config=config(num_obstacles=60), compressed=controller)
    try:
        hits = 0
        for _ in range(60):
            s.step()
            path = s._continuation_path()
            env = s.run.env
            feats = np.ascontiguousarray(env._core.compressed_state(0)[:27])
            local = quadratic_paths(db, feats[None])[0]
            np.testing.assert_allclose(_core.trajectory_path(raw_trajectory(db, feats).astype(np.float32)), local,
                                       atol=1e-4)
            st = env.env_state(0)
            c, sn = np.cos(st["yaw"]), np.sin(st["yaw"])
            world = local @ np.array([[c, sn], [-sn, c]]).T + np.array([st["x"], st["z"]])
            np.testing.assert_allclose(path["points"], world, atol=1e-3)
            first = int(env.state_path_hits(0, feats[None])[0])
            assert path["inside"].any() == (first > 0)
            hits += first > 0
    finally:
        s.close()
    with pytest.raises(ValueError, match="raw_trajectory"):
        _core.trajectory_path(np.zeros(11, np.float32))
