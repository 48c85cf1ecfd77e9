"""The collision-aware search (tasks/path_filter.hpp): each candidate frame's own played path,
tested against where the obstacles will be, re-ranks the decision's shortlist.

- the path test equals a numpy reference that plays the candidate's root deltas from the
  character's root and moves the obstacles by the env's rule frame by frame;
- the env's decisions equal a numpy brute force of the shortlist rule (search.hpp's
  brute_force_match_shortlist: the k nearest by plain distance, re-ranked by distance plus the
  path cost), and the filter changes decisions (not vacuous);
- the filter makes collisions rarer for the same actions;
- bad options name themselves.
On the synthetic skeleton and on a second one (Mixamo names, other channel orders)."""
import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.rl.policies import JoystickPolicy
from mmrl.rollout import apply_stage
from test_import_axes_fps import other_skeleton_database

SAMPLES = np.array([2, 4, 6, 8, 10, 15, 20, 25, 30])


@pytest.fixture(scope="module")
def synthetic_db():
    return mmrl.default_database()


@pytest.fixture(scope="module")
def mixamo_db(tmp_path_factory):
    return other_skeleton_database(tmp_path_factory.mktemp("mixamo_path"))


@pytest.fixture(params=["synthetic", "mixamo"])
def db(request, synthetic_db, mixamo_db):
    return synthetic_db if request.param == "synthetic" else mixamo_db


def config(**kw):
    base = dict(num_obstacles=60, obstacle_max_speed=1.0, path_filter=True, path_cost=50.0, path_candidates=32,
                max_steps=80)
    base.update(kw)
    return mmrl.get_task("obstacles").default_config().replace(**base)


def reference_path_distances(db, state, obstacles, rows, cfg, moving):
    """(rows, samples) distance from each row's played root (the root deltas from the character's
    root, decision.hpp) to the nearest obstacle where the env's motion rule puts it then."""
    dt = np.float32(1.0 / db.fps)
    half = np.float32(cfg.obstacle_square_half)
    rows = np.asarray(rows)
    x = np.full(rows.size, state["x"], np.float64)
    z = np.full(rows.size, state["z"], np.float64)
    yaw = np.full(rows.size, state["yaw"], np.float64)
    c = obstacles["centres"].astype(np.float32).copy()
    v = obstacles["velocities"].astype(np.float32).copy()
    h, a = obstacles["half_sizes"], obstacles["angles"]
    out = []
    for t in range(1, SAMPLES[-1] + 1):
        d = db.root_deltas[rows + t - 1].astype(np.float64)
        cy, sy = np.cos(yaw), np.sin(yaw)
        x, z, yaw = x + cy * d[:, 0] + sy * d[:, 1], z - sy * d[:, 0] + cy * d[:, 1], yaw + d[:, 2]
        if moving:
            c, v = moved_obstacles(c, v, dt, half)
        if t in SAMPLES:
            out.append(nearest_obstacle(x, z, c, h, a))
    return np.stack(out, axis=1)


def moved_obstacles(c, v, dt, half):
    """One frame of the env's obstacle motion: constant velocity, mirrored at the square's border."""
    c = c + v * dt
    over, under = c > half, c < -half
    c = np.where(over, 2 * half - c, np.where(under, -2 * half - c, c)).astype(np.float32)
    return c, np.where(over | under, -v, v)


def nearest_obstacle(x, z, c, h, a):
    """Distance from each point (x, z) to the nearest rectangle (centres c, half sizes h, angles a)."""
    dx = x[:, None] - c[None, :, 0]
    dz = z[:, None] - c[None, :, 1]
    u = np.cos(a)[None] * dx - np.sin(a)[None] * dz
    w = np.sin(a)[None] * dx + np.cos(a)[None] * dz
    du = np.maximum(np.abs(u) - h[None, :, 0], 0)
    dw = np.maximum(np.abs(w) - h[None, :, 1], 0)
    return np.sqrt(du * du + dw * dw).min(axis=1)


def reference_first_hits(dist, radius, horizon):
    """(first hit frame, 0 if clear; near: whether a sample within the horizon lies within 1 mm
    of the radius, where float rounding may decide)."""
    inside = SAMPLES <= horizon
    hit = (dist <= radius) & inside[None]
    first = np.where(hit.any(1), SAMPLES[np.argmax(hit, axis=1)], 0)
    near = (np.abs(dist - radius) < 1e-3)[:, inside].any(1)
    return first, near


def stepped(env, steps, seed, noise=0.8):
    """Steps env with noisy joystick actions; yields (states before, obstacles before, actions)."""
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    joy = JoystickPolicy(env.db, layout=env.observation_layout)
    for _ in range(steps):
        actions = (joy.act(obs) + rng.normal(0, noise, (env.num_envs, 12))).astype(np.float32)
        yield obs, actions
        obs, *_ = env.step(actions)


def test_path_test_equals_a_numpy_reference(db):
    cfg = config()
    env = mmrl.get_task("obstacles").make_vector_env(4, db=db, config=cfg, num_threads=1)
    apply_stage(mmrl.get_task("obstacles"), env, None)
    valid = np.flatnonzero(db.valid_mask)
    rng = np.random.default_rng(3)
    checked = hits = mismatched = 0
    for step, _ in enumerate(stepped(env, 25, 5)):
        for i in range(env.num_envs):
            rows = rng.choice(valid, 300)
            got = env.path_hits(i, rows)
            state = env.env_state(i)
            dist = reference_path_distances(db, state, env.obstacles(i), rows, cfg, state["max_speed"] > 0)
            want, near = reference_first_hits(dist, cfg.body_radius + cfg.path_margin, cfg.path_horizon)
            bad = (got != want) & ~near
            mismatched += int(bad.sum())
            checked += rows.size
            hits += int((want > 0).sum())
    assert mismatched == 0
    assert checked >= 20000 and 0.05 * checked < hits < 0.95 * checked, (checked, hits)


def test_a_shorter_horizon_tests_fewer_samples(synthetic_db):
    db = synthetic_db
    for horizon in (2, 10, 17):
        cfg = config(path_horizon=horizon)
        env = mmrl.get_task("obstacles").make_vector_env(2, db=db, config=cfg, num_threads=1)
        env.reset(seed=1)
        rows = np.flatnonzero(db.valid_mask)[::7]
        got = env.path_hits(0, rows)
        state = env.env_state(0)
        dist = reference_path_distances(db, state, env.obstacles(0), rows, cfg, state["max_speed"] > 0)
        want, near = reference_first_hits(dist, cfg.body_radius + cfg.path_margin, horizon)
        assert ((got == want) | near).all()
        assert got.max() <= horizon


def turned_queries(db, query, fan, step_degrees):
    """decision.cpp's shortlist_queries: the query, then its trajectory turned by +-m * step."""
    out = [query]
    scale = np.asarray(db.feature_scale, np.float64)[15:]
    mean = np.asarray(db.feature_mean, np.float64)[15:]
    raw = (query[15:] * scale + mean).reshape(-1, 2)
    for m in range(1, fan + 1):
        for side in (1, -1):
            a = np.radians(side * m * step_degrees)
            c, s = np.cos(a), np.sin(a)
            turned = np.stack([c * raw[:, 0] + s * raw[:, 1], -s * raw[:, 0] + c * raw[:, 1]], 1).reshape(-1)
            out.append(np.concatenate([query[:15], (turned - mean) / scale]))
    return out


def escape_queries(db, query, escapes):
    """decision.cpp's escape queries: the query's pose asking to stand, then to step back, left and
    right at 0.5 m/s facing ahead (X left, Z forward), then to walk at 1 m/s towards 0, +45, -45,
    +90, -90, +135, -135 and 180 degrees facing the way, then to run those ways at 2 m/s, at each
    of the +10/+20/+30-frame samples."""
    scale = np.asarray(db.feature_scale, np.float64)[15:]
    mean = np.asarray(db.feature_mean, np.float64)[15:]
    ways = [(0, 0, 0, 1, 0.5), (0, -1, 0, 1, 0.5), (1, 0, 0, 1, 0.5), (-1, 0, 0, 1, 0.5)]
    for speed in (1.0, 2.0):
        for degrees in (0, 45, -45, 90, -90, 135, -135, 180):
            a = np.radians(degrees)
            ways.append((np.sin(a), np.cos(a), np.sin(a), np.cos(a), speed))
    out = []
    for dx, dz, fx, fz, speed in ways[:escapes]:
        raw = []
        for frames in (10, 20, 30):
            d = speed * frames / db.fps
            raw += [dx * d, dz * d, fx, fz]
        out.append(np.concatenate([query[:15], (np.array(raw) - mean) / scale]))
    return out


def brute_force_shortlist(db, frame, action, low, high, extra, k, transition_cost=0.0, fan_k=1, escapes=0):
    """(match, cost, slack) by search.hpp's shortlist rule; extra(rows) gives the filter's cost.
    slack: how close the decision came to going another way (the shortlist's cut, the runner-up)."""
    rows = np.asarray(db.normalized_features, np.float64)
    query = np.concatenate([rows[frame, :15], np.clip(action, low, high)])
    d = ((rows - query) ** 2).sum(1)
    allowed = np.asarray(db.valid_mask, bool).copy()
    c = int(db.frame_clip[frame])
    start, stop = db.clip_ranges[c]
    allowed[max(start, frame - 20):min(stop, frame + 21)] = False
    cand = np.flatnonzero(allowed)
    ranked = cand[np.lexsort((cand, d[cand]))]
    order = ranked[:k]
    slack = d[ranked[k]] - d[ranked[k - 1]] if ranked.size > k else np.inf
    if escapes:
        members = set(order.tolist())
        for q in escape_queries(db, query, escapes):
            dq = ((rows[cand] - q) ** 2).sum(1)
            by_q = cand[np.lexsort((cand, dq))]
            members.update(by_q[:fan_k].tolist())
            slack = min(slack, np.sort(dq)[fan_k] - np.sort(dq)[fan_k - 1])
        order = np.array(sorted(members, key=lambda i: (d[i], i)))
    entries = [(c_, int(i)) for i, c_ in zip(order, d[order] + extra(order)) if np.isfinite(c_)]
    bound_c = np.inf
    if db.valid_mask[frame]:
        bound_c = d[frame] + extra(np.array([frame]))[0]
        if np.isfinite(bound_c):
            entries.append((bound_c - transition_cost, frame))
    entries.sort(key=lambda e: e[0])
    best_c, best_i = entries[0]
    if len(entries) > 1:
        slack = min(slack, entries[1][0] - best_c)
    return best_i, (bound_c if best_i == frame else best_c), slack


@pytest.mark.parametrize("escapes", [0, 4, 20])
def test_decisions_equal_a_brute_force_of_the_shortlist_rule(db, escapes):
    cfg = config(path_fan_candidates=3, path_escapes=escapes)
    task = mmrl.get_task("obstacles")
    env = task.make_vector_env(4, db=db, config=cfg, num_threads=2)
    apply_stage(task, env, None)
    low, high = env.single_action_space.low, env.single_action_space.high
    h = cfg.path_horizon

    def path_cost(first):
        return np.where(first > 0, cfg.path_cost * (2 - first / h), 0.0)

    compared = changed = by_escapes = 0
    # Twenty escape lists bring more near-ties (skipped below), so that case steps longer.
    for obs, actions in stepped(env, 60 if escapes < 12 else 200, 9):
        frames = env.current_frames()
        before = []
        for i in range(env.num_envs):
            extra = (lambda i: lambda rows: path_cost(env.path_hits(i, rows)))(i)
            no_extra = lambda rows: np.zeros(len(rows))
            full = brute_force_shortlist(db, frames[i], actions[i], low, high, extra, cfg.path_candidates,
                                         fan_k=3, escapes=escapes)
            no_escapes = full if not escapes else brute_force_shortlist(
                db, frames[i], actions[i], low, high, extra, cfg.path_candidates, fan_k=3)
            before.append((full, brute_force_shortlist(db, frames[i], actions[i], low, high, no_extra, 1)[0],
                           no_escapes[0]))
        env.step(actions)
        for i, ((want, want_cost, slack), plain, without_escapes) in enumerate(before):
            match, cost = env.last_step_decision(i)
            if slack < 1e-3:
                continue  # float32 rounding may order near-equal rows either way
            assert match == want, (i, match, want)
            assert cost == pytest.approx(want_cost, rel=1e-4, abs=1e-4)
            compared += 1
            changed += match != plain
            by_escapes += match != without_escapes
    assert compared >= 120
    assert changed >= 5, "the path filter never changed a decision: the test tests nothing"
    if escapes:
        assert by_escapes >= 1, "the escapes never changed a decision: the test tests nothing"


def test_the_filter_makes_collisions_rarer_for_the_same_actions(synthetic_db):
    task = mmrl.get_task("obstacles")
    rates = {}
    for on in (False, True):
        env = task.make_vector_env(200, db=synthetic_db, config=config(path_filter=on, path_cost=200.0),
                                   num_threads=2)
        apply_stage(task, env, None)
        from mmrl.rollout import first_episodes

        r = first_episodes(env, JoystickPolicy(synthetic_db), seed=4)
        rates[on] = r["collision"].mean()
    assert rates[True] < rates[False] - 0.03, rates


@pytest.mark.parametrize("option, value, needle", [
    ("path_horizon", 1, "path_horizon"), ("path_horizon", 31, "path_horizon"),
    ("path_cost", -1.0, "path_cost"), ("path_cost", float("nan"), "path_cost"),
    ("path_margin", -0.1, "path_margin"), ("path_margin", float("inf"), "path_margin"),
    ("path_candidates", -1, "path_candidates"), ("path_candidates", 257, "path_candidates"),
    ("path_fan_degrees", 0.0, "path_fan_degrees"),
    ("path_fan_degrees", 91.0, "path_fan_degrees"), ("path_fan_candidates", 0, "path_fan_candidates"),
    ("path_escapes", 21, "path_escapes"), ("path_escapes", -1, "path_escapes"),
    ("path_margin", 3.0, "body_radius + path_margin"), ("body_radius", 3.5, "body_radius"),
])
def test_bad_filter_options_name_the_option(synthetic_db, option, value, needle):
    with pytest.raises(ValueError, match=needle.replace("+", r"\+")):
        mmrl.get_task("obstacles").make_vector_env(2, db=synthetic_db, config=config(**{option: value}))


def test_too_many_escape_rows_name_both_options(synthetic_db):
    with pytest.raises(ValueError, match="path_escapes x path_fan_candidates must be at most 256, got 12 x 22"):
        mmrl.get_task("obstacles").make_vector_env(
            2, db=synthetic_db, config=config(path_escapes=12, path_fan_candidates=22))


def test_path_hits_refuses_rows_that_cannot_be_matched(synthetic_db):
    env = mmrl.get_task("obstacles").make_vector_env(2, db=synthetic_db, config=config())
    env.reset(seed=0)
    invalid = int(np.flatnonzero(~synthetic_db.valid_mask)[0])
    for rows in ([-1], [synthetic_db.num_frames], [invalid]):
        with pytest.raises(ValueError, match="rows"):
            env.path_hits(0, np.array(rows, np.int64))


def test_runtime_files_carry_the_filter_and_a_loader_can_require_it(tmp_path, synthetic_db):
    from mmrl.export.runtime_export import write_controller
    from mmrl.export.runtime_file import read_sections, write_sections
    ControllerFileError = _core.ControllerFileError
    from test_runtime import random_obstacle_policy

    policy = random_obstacle_policy(5)
    with_filter, without = tmp_path / "with.mmrl", tmp_path / "without.mmrl"
    write_controller(with_filter, synthetic_db, policy, "obstacles", config(path_cost=float("inf")))
    write_controller(without, synthetic_db, policy, "obstacles", config(path_filter=False))
    loaded = _core.RuntimeController.load(str(with_filter), require_path_filter=True)
    assert loaded.task_name == "obstacles"
    _core.RuntimeController.load(str(without))  # nothing required: loads
    with pytest.raises(ControllerFileError, match="requires the collision-aware search.*path_filter is off"):
        _core.RuntimeController.load(str(without), require_path_filter=True)
    # A file that switches the filter on but lacks its numbers (hand-edited, or truncated tables).
    sections = read_sections(with_filter)
    keys = list(sections["task.keys"])
    values = np.asarray(sections["task.values"])
    keep = [k != "path_horizon" for k in keys]
    sections["task.keys"] = [k for k, ok in zip(keys, keep) if ok]
    sections["task.values"] = values[np.asarray(keep)]
    broken = tmp_path / "broken.mmrl"
    write_sections(broken, sections)
    with pytest.raises(ControllerFileError, match="path_filter is on but the file lacks task.path_horizon"):
        _core.RuntimeController.load(str(broken))


def test_runtime_files_carry_the_escape_table(tmp_path, synthetic_db):
    """The export writes the escapes' table (task.escape_table), so the runtime need not find it
    at load; the runtime decides with the file's table; a broken one is refused naming it."""
    from mmrl.export.runtime_export import write_controller
    from mmrl.export.runtime_file import read_sections, write_sections
    from test_runtime import random_obstacle_policy

    # Two near candidates: the filter often finds both dear, and the escapes decide.
    cfg = config(path_cost=10000.0, path_escapes=20, path_fan_candidates=2, path_candidates=2, num_obstacles=100,
                 obstacle_max_speed=1.0)
    policy = random_obstacle_policy(5)
    path = tmp_path / "escapes.mmrl"
    write_controller(path, synthetic_db, policy, "obstacles", cfg)
    sections = read_sections(path)
    table = np.asarray(sections["task.escape_table"])
    assert table.shape == (synthetic_db.num_frames, 40) and table.dtype == np.int32
    np.testing.assert_array_equal(table, synthetic_db.matcher.escape_table(synthetic_db._db, 20, 2))
    # No table without escapes.
    plain = tmp_path / "plain.mmrl"
    write_controller(plain, synthetic_db, policy, "obstacles", config(path_cost=10000.0))
    assert "task.escape_table" not in read_sections(plain)

    def rewritten(name, **changes):
        out = dict(sections, **changes)
        write_sections(tmp_path / name, out)
        return str(tmp_path / name)

    def decisions(file):
        from mmrl.rollout import FullPath

        c = _core.RuntimeController.load(file)
        out = []
        for seed in range(4):
            fp = FullPath(mmrl.get_task("obstacles"), synthetic_db, config=cfg, seed=seed, record=False)
            ch = _core.RuntimeCharacter(c, *fp.character.root, fp.character.frame)
            ch.set_target(*fp.target)
            for _ in range(60):
                o = fp.env.obstacles(0)
                ch.set_obstacles(*(np.ascontiguousarray(o[k], np.float32)
                                   for k in ("centres", "half_sizes", "angles", "velocities")))
                step = fp.step(c.act(fp.obs))
                for _ in range(step["step_frames"]):
                    ch.advance_frame()
                out.append((step["res"].match, ch.last_decision()["match"]))
                if step["done"]:
                    break
        return np.array(out)

    honest = decisions(str(path))
    np.testing.assert_array_equal(honest[:, 1], honest[:, 0])  # the file's table: the env's decisions
    # Without the section (a file written before it) the runtime builds the same table.
    without = {k: v for k, v in sections.items() if k != "task.escape_table"}
    write_sections(tmp_path / "without.mmrl", without)
    np.testing.assert_array_equal(decisions(str(tmp_path / "without.mmrl")), honest)
    # A table of no rows loads (every entry may be -1) and is the one the runtime uses.
    empty = decisions(rewritten("empty.mmrl", **{"task.escape_table": np.full_like(table, -1)}))
    assert np.any(empty[:len(honest), 1] != honest[:len(empty), 1]), "the runtime ignored the file's table"
    bad = table.copy()
    bad[3, 5] = synthetic_db.num_frames
    with pytest.raises(_core.ControllerFileError, match="task.escape_table.*entry 125"):
        _core.RuntimeController.load(rewritten("bad.mmrl", **{"task.escape_table": bad}))
    with pytest.raises(_core.ControllerFileError, match="task.escape_table"):
        _core.RuntimeController.load(rewritten("shape.mmrl", **{"task.escape_table": table[:, :20].copy()}))
    with pytest.raises(_core.ControllerFileError, match="escape_table' is present but the file's search takes no"):
        _core.RuntimeController.load(rewritten("noesc.mmrl", **{"task.escape_table": table,
                                                                  **read_sections(plain)}))


@pytest.mark.parametrize("network", ["small-cnn", "mlp"])
def test_the_cheap_networks_train_export_and_run_in_the_runtime(tmp_path, network):
    """--set network=NAME builds the task's network; its actor exports to the runtime, which acts
    as torch does."""
    from mmrl.cli import main
    from mmrl.runs import RunDir
    from test_runtime import sample_observations

    run = tmp_path / network
    assert main(["train", "obstacles", "--steps", "1024", "--envs", "8", "--out", str(run), "--no-progress",
                 "--set", f"network={network}"]) == 0
    assert main(["export", str(run), "-o", str(tmp_path / "c.mmrl")]) == 0
    r = RunDir(run)
    policy = r.policy()
    kind = {"small-cnn": "ObstacleActorCritic", "mlp": "MLPActorCritic"}[network]
    assert type(policy.model).__name__ == kind
    obs = sample_observations(r.task, r.database(), r.task_config(r.task), policy, 200, seed=3)
    c = _core.RuntimeController.load(str(tmp_path / "c.mmrl"), require_path_filter=True)
    ours = np.stack([c.act(o) for o in obs])
    ref = policy.act(obs)
    assert np.max(np.abs(ours - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-5
    actor = sum(p.numel() for p in policy.model.actor.parameters())
    assert actor < 100_000  # the paper's actor has 572,732 weights


def test_train_path_filter_off_trains_without_the_search_and_keeps_it_for_everything_after(tmp_path,
                                                                                            monkeypatch):
    """train_path_filter=false: the training envs run without the collision-aware search, while
    config.json, evaluation and the exported controller keep path_filter (and the exported policy
    runs in the runtime as torch does)."""
    from mmrl.cli import main
    from mmrl.runs import RunDir
    from mmrl.tasks.obstacles import ObstaclesVectorEnv
    from test_runtime import sample_observations

    built = []
    original = ObstaclesVectorEnv.__init__

    def recording(self, *args, **kwargs):
        original(self, *args, **kwargs)
        built.append((self.num_envs, self.config.path_filter))

    monkeypatch.setattr(ObstaclesVectorEnv, "__init__", recording)
    run = tmp_path / "run"
    assert main(["train", "obstacles", "--steps", "1024", "--envs", "8", "--out", str(run), "--no-progress",
                 "--set", "network=small-cnn", "--set", "train_path_filter=false"]) == 0
    assert built[0] == (8, False), built  # the training envs: no search
    r = RunDir(run)
    cfg = r.task_config(r.task)
    assert cfg.path_filter and not cfg.train_path_filter
    assert r.task.train_config(cfg).path_filter is False and r.task.train_config(cfg.replace(
        train_path_filter=True)).path_filter is True
    assert not hasattr(cfg.to_core(_core.ObstacleTaskConfig), "train_path_filter")  # the trainer's, not the core's
    assert main(["export", str(run), "-o", str(tmp_path / "c.mmrl")]) == 0
    c = _core.RuntimeController.load(str(tmp_path / "c.mmrl"), require_path_filter=True)
    policy = r.policy()
    obs = sample_observations(r.task, r.database(), cfg, policy, 100, seed=4)
    assert obs.shape[1] == 529
    ours = np.stack([c.act(o) for o in obs])
    ref = policy.act(obs)
    assert np.max(np.abs(ours - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-5


def test_a_runtime_file_whose_policy_does_not_read_its_observation_is_refused(tmp_path, synthetic_db):
    from mmrl.export.runtime_export import write_controller
    from mmrl.export.runtime_file import read_sections, write_sections
    from test_runtime import random_obstacle_policy

    path = tmp_path / "c.mmrl"
    write_controller(path, synthetic_db, random_obstacle_policy(2), "obstacles", config())
    sections = read_sections(path)
    sections["task.core"] = ["plane"]  # the plane core reads 17 floats; this policy 529
    write_sections(path, sections)
    with pytest.raises(_core.ControllerFileError, match=r"reads 529 observations; the plane task's are 17 \(pose 15, goal 2\)"):
        _core.RuntimeController.load(str(path))


@pytest.mark.parametrize("name, on, now", [("hit_played", True, False), ("bias_yields", True, False),
                                           ("observe_continuation", True, False), ("path_fan", 2, 0),
                                           ("previous_map_lag", 5, 1)])
def test_a_retired_option_is_refused_everywhere_with_one_line(name, on, now, tmp_path, capsys, synthetic_db):
    """An experiment's option that was removed (docs/obstacles.md, "Retired options"): --set gives
    one line and exit 2; a config.json that ran it on is refused naming it, one that has the value
    the code now always has still loads; a controller file with it on is refused by the runtime."""
    import json

    from mmrl.cli import main
    from mmrl.errors import InputError
    from mmrl.export.runtime_export import write_controller
    from mmrl.export.runtime_file import read_sections, write_sections
    from mmrl.runs import RunDir
    from test_runtime import random_obstacle_policy

    assert main(["train", "obstacles", "--steps", "512", "--out", str(tmp_path / "x"), "--no-progress",
                 "--set", f"{name}={str(on).lower()}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{name!r} was an experiment's and is retired" in err[0], err
    task = mmrl.get_task("obstacles")
    with pytest.raises(ValueError, match="retired"):
        task.default_config().replace(**{name: on})
    for strict in (False, True):  # old runs' saved default (strict: what an RLlib worker reads)
        assert task.config_from_dict({name: now, "num_obstacles": 7}, strict=strict).num_obstacles == 7
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"task": "obstacles", "task_config": {name: on}}))
    with pytest.raises(InputError, match=f"config.json: .*{name}"):
        RunDir(run).task_config()
    old = tmp_path / "old-run"  # a run that trained with it on cannot be resumed without it
    assert main(["train", "obstacles", "--steps", "256", "--envs", "4", "--out", str(old), "--no-progress",
                 "--set", "network=small-cnn"]) == 0
    config_file = old / "config.json"
    saved = json.loads(config_file.read_text())
    saved["task_config"][name] = on
    config_file.write_text(json.dumps(saved))
    capsys.readouterr()
    assert main(["train", "--resume", str(old), "--steps", "512", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0] and name in err[0], err
    path = tmp_path / "c.mmrl"
    write_controller(path, synthetic_db, random_obstacle_policy(2), "obstacles", config())
    sections = read_sections(path)
    sections["task.keys"] = list(sections["task.keys"]) + [name]
    sections["task.values"] = np.append(sections["task.values"], float(on))
    write_sections(path, sections)
    if name == "hit_played":  # a training option: the runtime never read it
        _core.RuntimeController.load(str(path))
    else:
        with pytest.raises(_core.ControllerFileError, match=f"task.{name} is {float(on):g}: an experiment's option"):
            _core.RuntimeController.load(str(path))
        sections["task.values"][-1] = float(now)  # the value the code now always has: loads
        write_sections(path, sections)
        _core.RuntimeController.load(str(path))


def test_an_unknown_network_is_refused(tmp_path, capsys):
    from mmrl.cli import main

    assert main(["train", "obstacles", "--steps", "512", "--out", str(tmp_path / "x"), "--no-progress",
                 "--set", "network=resnet"]) == 2
    assert "network" in capsys.readouterr().err
    assert main(["train", "plane", "--steps", "512", "--out", str(tmp_path / "y"), "--no-progress",
                 "--set", "network=mlp"]) == 2
    assert "one network" in capsys.readouterr().err
