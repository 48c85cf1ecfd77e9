"""Hostile arrays through the Python API (issue 18, item 5): property tests (hypothesis) over
every public function that takes arrays.

Each argument gets variants of a valid value: NaN and inf, other dtypes, non-contiguous
(strided, Fortran order, transposed), zero-size, other ranks, huge shapes (broadcast views of
2**31+ rows: no memory behind them), read-only buffers, Python lists, None and scalars, and for
integer arrays out-of-range values. Every call either works, and then gives what the same call
on the clean equivalent array gives, or raises a TypeError, ValueError, IndexError or
MemoryError whose message names the argument. A segfault would end the test run.

Arrays freed (or changed) while C++ holds them: tests/test_hostile_memory.py.
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import mmrl
from mmrl import _core

ERRORS = (TypeError, ValueError, IndexError, MemoryError, OverflowError)
HUGE = 2**31 + 3
#: The default (synthetic) database's frames: 8 s at 30 fps per clip; the first frame past its end.
FRAMES = mmrl.motion.synth.DEFAULT_NUM_CLIPS * 240
EXAMPLES = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
DTYPES = [np.float64, np.float16, np.int32, np.int64, np.uint8, np.uint64, np.bool_, np.complex64, object, "U3"]


@st.composite
def hostile(draw, valid: np.ndarray, values=()):
    """(kind, array-like): a variant of ``valid``; ``values``: bad entries for integer arrays."""
    kinds = ["valid", "nonfinite", "dtype", "strided", "fortran", "zero", "rank", "huge", "readonly", "python"]
    kinds += ["value"] if values else []
    kind = draw(st.sampled_from(kinds))
    a = valid.copy()
    if kind == "nonfinite" and a.dtype.kind == "f" and a.size:
        a.flat[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    elif kind == "dtype":
        dtype = draw(st.sampled_from(DTYPES))
        a = a.astype(dtype) if dtype != "U3" else a.astype(str).astype("U3")
    elif kind == "strided" and a.ndim:
        step = draw(st.integers(2, 3))
        a = np.repeat(a, step, axis=0)[::step]
    elif kind == "fortran" and a.ndim > 1:
        a = np.asfortranarray(a) if draw(st.booleans()) else np.ascontiguousarray(a.T).T
    elif kind == "zero" and a.ndim:
        a = np.take(a, [], axis=draw(st.integers(0, a.ndim - 1)))
    elif kind == "rank":
        a = draw(st.sampled_from([a[None], a.reshape(-1), a[..., None], np.asarray(a.flat[0] if a.size else 0)]))
    elif kind == "huge" and a.ndim and a.size:
        a = np.broadcast_to(a[:1], (HUGE,) + a.shape[1:])
    elif kind == "readonly":
        a.flags.writeable = False
    elif kind == "python":
        a = draw(st.sampled_from([a.tolist(), None, 1.5, "abc", [[1, 2], [3]]]))
    elif kind == "value" and a.size:
        a = a.astype(np.int64)  # room for every bad value
        a.flat[draw(st.integers(0, a.size - 1))] = draw(st.sampled_from(list(values)))
    return kind, a


def refused_or_equal(call, names, args, reference=None):
    """Run ``call(*args)``; an error must name one of ``names``; a result must equal
    ``reference()`` (the same call on clean arrays) when given."""
    names = (names,) if isinstance(names, str) else names
    try:
        result = call(*args)
    except ERRORS as error:
        assert any(n in str(error) for n in names), f"{type(error).__name__}: {error} names none of {names}"
        return None
    if reference is not None:
        expected = reference()
        for got, want in zip(_flat(result), _flat(expected)):
            np.testing.assert_array_equal(got, want)
    return result


def _flat(x):
    return list(x) if isinstance(x, tuple) else [x]


def _clean(a, dtype):
    """The clean array a variant stands for, or None when it has none (then it must be refused)."""
    try:
        arr = np.asarray(a) if not isinstance(a, (str, type(None))) else None
    except ValueError:  # ragged lists
        return None
    if arr is None or arr.dtype.kind not in "fiub" or arr.size >= HUGE:
        return None
    return np.ascontiguousarray(arr, dtype=dtype)


@pytest.fixture(scope="module")
def db():
    d = mmrl.default_database()
    assert d.num_frames == FRAMES  # the boundary the cases below draw
    return d


# ----------------------------------------------------------------------------- database and search

@EXAMPLES
@given(case=hostile(np.zeros((5, 27), np.float32)))
def test_database_match_queries(db, case):
    kind, q = case
    valid = db.features[[10, 200, 900, 1500, 3000]]
    q = valid + q if kind == "valid" else q
    ref = None
    if isinstance(q, np.ndarray) and q.dtype == np.float32 and q.shape[-1:] == (27,) and q.ndim == 2:
        if q.shape[0] < HUGE and np.isfinite(q).all():
            clean = np.ascontiguousarray(q)
            ref = lambda: db.matcher.brute_force(db.normalize(clean))  # noqa: E731
    refused_or_equal(db.match, "queries", (q,), ref)


@EXAMPLES
@given(case=hostile(np.array([10, 200, 900, 1500, 3000], np.int64), values=[-2, 10**9, -(2**63), 2**63 - 1]))
def test_database_match_bound_indices(db, case):
    _, bound = case
    q = db.features[[11, 201, 901, 1501, 3001]]
    refused_or_equal(lambda b: db.match(q, bound_indices=b), "bound_indices", (bound,))


@EXAMPLES
@given(case=hostile(np.array([[0, 30], [190, 230], [880, 920], [1480, 1520], [2980, 3020]], np.int64),
                    values=[-5, 10**9, -(2**63), 2**63 - 1]))
def test_database_match_exclude(db, case):
    kind, exclude = case
    q = db.features[[11, 201, 901, 1501, 3001]]
    result = refused_or_equal(lambda e: db.match(q, exclude=e), "exclude", (exclude,))
    if result is not None and kind in ("valid", "readonly", "value"):  # any window: never a row inside it
        e = np.asarray(exclude)
        assert not ((result[0] >= e[:, 0]) & (result[0] < e[:, 1])).any()


@EXAMPLES
@given(case=hostile(np.zeros((4, 27), np.float32)))
def test_database_normalize_and_denormalize(db, case):
    _, f = case
    clean = _clean(f, np.float32)
    ok = clean is not None and np.asarray(f).dtype.kind in "fiu" and clean.shape[-1:] == (27,) and clean.ndim >= 1
    refused_or_equal(db.normalize, "features", (f,),
                     (lambda: ((clean - db.feature_mean) / db.feature_scale).astype(np.float32)) if ok else None)
    refused_or_equal(db.denormalize, "normalized", (f,),
                     (lambda: (clean * db.feature_scale + db.feature_mean).astype(np.float32)) if ok else None)
    if not ok:  # nothing clean to stand for: refused
        with pytest.raises(ERRORS):
            db.normalize(f)


@EXAMPLES
@given(case=hostile(np.array([0, 5, 1000, 6000], np.int64), values=[-1, -(2**63), 2**62, FRAMES]))
def test_database_controller_windows(db, case):
    kind, frames = case
    ref = None
    if kind in ("valid", "readonly", "strided"):
        clean = np.asarray(frames, np.int64)
        ranges = db.clip_ranges[db.frame_clip[clean]]
        ref = lambda: np.stack([np.maximum(ranges[:, 0], clean - 20), np.minimum(ranges[:, 1], clean + 21)], 1)  # noqa: E731
    result = refused_or_equal(db.controller_windows, "frames", (frames,), ref)
    if kind == "value" or kind == "dtype" and np.asarray(frames).dtype.kind not in "iu":
        assert result is None  # out-of-range frames (every value drawn is), floats, bools, objects: refused


@EXAMPLES
@given(case=hostile(np.random.default_rng(0).random((40, 3), dtype=np.float32)))
def test_kdtree_and_matcher_points(case):
    kind, points = case
    queries = np.random.default_rng(1).random((6, 3), dtype=np.float32)
    tree = refused_or_equal(mmrl.KDTree, "points", (points,))
    matcher = refused_or_equal(lambda p: _core.Matcher(p, np.ones(40, bool)), ("points", "valid_mask"), (points,))
    if tree is not None:  # accepted: only clean float32 points, and exact answers
        p = np.asarray(points, np.float32)
        idx, dist = tree.query(queries)
        nearest = ((queries[:, None] - p[None]) ** 2).sum(-1).argmin(1) if len(p) else np.full(6, -1)
        np.testing.assert_array_equal(np.asarray(idx).ravel(), nearest)
    if matcher is not None:
        assert matcher.num_rows == 40


@EXAMPLES
@given(case=hostile(np.random.default_rng(2).random((6, 3), dtype=np.float32)))
def test_kdtree_and_matcher_queries(case):
    _, queries = case
    points = np.random.default_rng(0).random((40, 3), dtype=np.float32)
    tree, matcher = mmrl.KDTree(points), _core.Matcher(points, np.ones(40, bool))
    clean = queries if isinstance(queries, np.ndarray) and queries.dtype == np.float32 else None
    ref = (lambda: matcher.brute_force(np.ascontiguousarray(clean))) if clean is not None and clean.ndim == 2 \
        and clean.shape[1] == 3 and len(clean) < HUGE and np.isfinite(clean).all() else None
    refused_or_equal(tree.query, "queries", (queries,))
    refused_or_equal(matcher.match, "queries", (queries,), ref)
    refused_or_equal(matcher.brute_force, "queries", (queries,))


@EXAMPLES
@given(case=hostile(np.ones(40, bool)))
def test_matcher_valid_mask(case):
    _, mask = case
    points = np.random.default_rng(0).random((40, 3), dtype=np.float32)
    refused_or_equal(lambda m: _core.Matcher(points, m), "valid_mask", (mask,))


@EXAMPLES
@given(case=hostile(np.array([0, 7, FRAMES - 1], np.int64), values=[-1, FRAMES, -(2**63), 2**63 - 1]))
def test_database_global_positions_frames(db, case):
    _, frames = case
    refused_or_equal(lambda f: _core.database_global_positions(db._db, f), "frames", (frames,))


# ----------------------------------------------------------------------------- envs

def _buffers(core, n, obstacles):
    b = dict(actions=np.zeros((n, 12), np.float32), obs=np.zeros((n, core.obs_dim), np.float32),
             rewards=np.zeros(n, np.float32), terminated=np.zeros(n, np.uint8), truncated=np.zeros(n, np.uint8),
             success=np.zeros(n, np.uint8))
    if obstacles:
        b.update(collision=np.zeros(n, np.uint8), hits=np.zeros(n, np.int32))
    b.update(final_obs=np.zeros((n, core.obs_dim), np.float32), episode_return=np.zeros(n, np.float32),
             episode_length=np.zeros(n, np.int32))
    return b


@pytest.fixture(scope="module", params=["plane", "obstacles"])
def vector_env(request, db):
    overrides = {"num_obstacles": 10} if request.param == "obstacles" else {}
    env = mmrl.get_task(request.param).make_vector_env(3, db=db, num_threads=1, **overrides)
    env.reset(seed=0)
    yield request.param, env
    env.close()


@EXAMPLES
@given(case=hostile(np.full((3, 12), 0.1, np.float32)))
def test_vector_env_step_actions(vector_env, case):
    _, env = vector_env
    kind, actions = case
    result = refused_or_equal(env.step, "actions", (actions,))
    if result is not None:
        obs, rewards, terminated, truncated, _ = result
        assert obs.shape == (3, env.single_observation_space.shape[0]) and np.isfinite(obs).all()
        assert np.isfinite(rewards).all()
        assert kind not in ("nonfinite", "huge", "zero") or not np.asarray(actions).size


@EXAMPLES
@given(data=st.data())
def test_core_env_step_buffers(vector_env, data):
    """The batched C++ step fills buffers Python allocated: each one must be exactly right."""
    task, env = vector_env
    core = env.unwrapped._core
    buffers = _buffers(core, 3, task == "obstacles")
    name = data.draw(st.sampled_from(sorted(buffers)))
    kind, bad = data.draw(hostile(buffers[name], values=[-1, 255, 2**31 - 1] if name != "actions" else ()))
    if name == "actions" and kind == "valid":
        bad = np.full((3, 12), 0.1, np.float32)
    args = dict(buffers, **{name: bad})
    result = refused_or_equal(lambda: core.step(**args), name, ())
    if result is None and kind not in ("valid",):
        return
    assert np.isfinite(args["obs"]).all() if isinstance(args["obs"], np.ndarray) else True


@EXAMPLES
@given(data=st.data())
def test_core_env_frame_and_match_buffers(vector_env, data):
    _, env = vector_env
    core = env.unwrapped._core
    method, name, valid = data.draw(st.sampled_from([
        ("current_frames", "out", np.zeros(3, np.int64)), ("step_frames", "out", np.zeros(3, np.int32)),
        ("reset", "obs", np.zeros((3, core.obs_dim), np.float32))]))
    _, bad = data.draw(hostile(valid))
    call = (lambda a: core.reset(0, a)) if method == "reset" else getattr(core, method)
    refused_or_equal(call, name, (bad,))
    if method == "current_frames" and isinstance(bad, np.ndarray) and bad.dtype == np.int64 and bad.shape == (3,) \
            and bad.flags.writeable and bad.flags.c_contiguous:
        assert ((bad >= 0) & (bad < env.unwrapped.db.num_frames)).all()
    _, transitions = data.draw(hostile(np.zeros(3, np.uint8)))
    refused_or_equal(lambda t: core.last_step_transitions(t, np.zeros(3, np.float32)), "transitions", (transitions,))


@EXAMPLES
@given(index=st.sampled_from([-1, 3, 2**31 - 1, -(2**31)]),
       frame=st.sampled_from([-1, FRAMES, 2**40]), x=st.sampled_from([np.nan, np.inf, 1e30, 0.0]))
def test_core_env_indices_frames_and_roots(vector_env, index, frame, x):
    _, env = vector_env
    core = env.unwrapped._core
    with pytest.raises(IndexError, match="index"):
        core.state(index)
    with pytest.raises(IndexError, match="index"):
        core.set_target(index, 1.0, 1.0)
    with pytest.raises((ValueError, TypeError), match="frame"):
        core.set_state(0, frame, 0.0, 0.0, 0.0)
    if not np.isfinite(x):
        with pytest.raises(ValueError, match="finite"):
            core.set_state(0, 100, x, 0.0, 0.0)
        with pytest.raises(ValueError, match="finite"):
            core.set_target(0, x, 0.0)


@EXAMPLES
@given(data=st.data())
def test_obstacle_env_set_obstacles_and_action_hits(db, data):
    env = mmrl.get_task("obstacles").make_vector_env(1, db=db, num_threads=1, num_obstacles=8)
    env.reset(seed=0)
    core = env.unwrapped._core
    valid = dict(centres=np.full((8, 2), 3.0, np.float32), half_sizes=np.full((8, 2), 0.3, np.float32),
                 angles=np.zeros(8, np.float32), velocities=np.zeros((8, 2), np.float32))
    name = data.draw(st.sampled_from(sorted(valid)))
    _, bad = data.draw(hostile(valid[name]))
    refused_or_equal(lambda a: core.set_obstacles(0, **dict(valid, **{name: a})), (name, "obstacle"), (bad,))
    _, action = data.draw(hostile(np.zeros(12, np.float32)))
    refused_or_equal(lambda a: core.action_hits(0, a), "action", (action,))
    env.close()


# ----------------------------------------------------------------------------- character, metrics, runtime

@EXAMPLES
@given(query=hostile(np.zeros(12, np.float32)), target=hostile(np.array([1.0, 2.0])),
       position=hostile(np.array([0.5, -0.5])))
def test_controller_step_observation_reset(db, query, target, position):
    ctrl = mmrl.Character(db)
    ctrl.reset()
    refused_or_equal(ctrl.step, "trajectory_query", (query[1],))
    clean = _clean(target[1], np.float64)
    ok = clean is not None and np.asarray(target[1]).dtype.kind in "fiu" and clean.shape == (2,) \
        and np.isfinite(clean).all()
    obs = refused_or_equal(ctrl.observation, "target", (target[1],),
                           (lambda: ctrl.observation(clean.tolist())) if ok else None)
    assert (obs is not None) == ok
    refused_or_equal(lambda p: ctrl.reset(position=p), "position", (position[1],))


@EXAMPLES
@given(positions=hostile(np.random.default_rng(0).random((6, 21, 3))),
       contacts=hostile(np.ones((6, 2), bool)), frames=hostile(np.arange(100, 106), values=[-1, FRAMES]),
       roots=hostile(np.zeros((6, 3))))
def test_metrics(db, positions, contacts, frames, roots):
    from mmrl import metrics

    refused_or_equal(lambda p, c: metrics.foot_contact_speeds(p, c, [4, 8], 30.0), ("positions", "contacts", "foot_joints"),
                     (positions[1], contacts[1]))
    refused_or_equal(lambda p, r, f: metrics.pose_jumps(p, r, f, db), ("positions", "roots", "frames"),
                     (positions[1], roots[1], frames[1]))
    refused_or_equal(lambda j: metrics.pose_jumps(np.zeros((3, 21, 3)), np.zeros((3, 3)), np.arange(3), db, j),
                     "joints", ([0, 21] if frames[0] == "value" else [0, 1],))
    refused_or_equal(lambda t: metrics.transitions_per_second(t, 6, 30.0), "transitions", (contacts[1],))


@EXAMPLES
@given(data=st.data())
def test_ik_two_bone(data):
    valid = dict(hip=np.array([0, 1, 0], np.float32), knee=np.array([0, 0.5, 0.05], np.float32),
                 ankle=np.zeros(3, np.float32), target=np.array([0, 0.1, 0.1], np.float32))
    name = data.draw(st.sampled_from(sorted(valid) + ["pole"]))
    _, bad = data.draw(hostile(valid.get(name, np.array([0, 0, 1], np.float32))))
    refused_or_equal(lambda a: _core.ik_two_bone(**dict(valid, **{name: a})), (name, "ik_two_bone"), (bad,))


@EXAMPLES
@given(data=st.data())
def test_motion_from_pose_and_bvh_writing(db, data):
    valid = dict(local_translations=np.ascontiguousarray(db.bone_translations[:5]),
                 local_rotations=np.ascontiguousarray(db.bone_rotations[:5]))
    name = data.draw(st.sampled_from(sorted(valid)))
    kind, bad = data.draw(hostile(valid[name]))
    motion = refused_or_equal(lambda a: _core.motion_from_pose(db._db, **dict(valid, **{name: a})),
                              ("local_translations", "local_rotations"), (bad,))
    if motion is not None:  # written BVH text parses back to the same number of frames
        assert mmrl.parse_bvh(motion.to_bvh()).num_frames == motion.num_frames


@pytest.fixture(scope="module")
def runtime_files(db, tmp_path_factory):
    from mmrl.export.runtime_export import write_controller
    from mmrl.tasks.obstacles import ObstaclesConfig
    from mmrl.tasks.plane import PlaneConfig
    from test_runtime import random_obstacle_policy, random_plane_policy

    out = tmp_path_factory.mktemp("hostile_runtime")
    write_controller(out / "p.mmrl", db, random_plane_policy(1), "plane", PlaneConfig())
    write_controller(out / "o.mmrl", db, random_obstacle_policy(1), "obstacles", ObstaclesConfig(num_obstacles=8))
    return out / "p.mmrl", out / "o.mmrl"


@EXAMPLES
@given(obs=hostile(np.zeros(17, np.float32)), centres=hostile(np.full((8, 2), 3.0, np.float32)),
       angles=hostile(np.zeros(8, np.float32)), dt=st.sampled_from([np.nan, -1.0, np.inf, 1e9, 2.0**24, 61.0, 60.0]))
def test_runtime_act_set_obstacles_update(runtime_files, obs, centres, angles, dt):
    plane = _core.RuntimeController.load(str(runtime_files[0]))
    refused_or_equal(plane.act, "obs", (obs[1],))
    character = _core.RuntimeCharacter(_core.RuntimeController.load(str(runtime_files[1])), 0.0, 0.0, 0.0)
    half = np.full((8, 2), 0.3, np.float32)
    refused_or_equal(lambda c, a: character.set_obstacles(c, half, a), ("centres", "angles", "half_sizes", "obstacle"),
                     (centres[1], angles[1]))
    refused_or_equal(character.update, "dt", (dt,))


def test_runtime_update_refuses_a_dt_it_would_loop_on_for_ever(runtime_files):
    # From 2**24 s on, `clock -= 1/30` leaves a float clock unchanged: update never returned.
    character = _core.RuntimeCharacter(_core.RuntimeController.load(str(runtime_files[0])), 0.0, 0.0, 0.0)
    for dt in (2.0**24, 1e9, 86400.0):
        with pytest.raises(ValueError, match="dt must be finite, >= 0 and at most 60 s"):
            character.update(dt)
    before = character.frames_shown
    character.update(60.0)  # the largest dt allowed: 1800 frames at 30 fps
    assert character.frames_shown - before == 1800
