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
    return mmrl.default_database()


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
@given(case=hostile(np.array([0, 5, 1000, 6000], np.int64), values=[-1, -(2**63), 2**62, 6480]))
def test_database_controller_windows(db, case):
    kind, frames = case
    ref = None
    if kind in ("valid", "readonly", "strided"):
        clean = np.asarray(frames, np.int64)
        ranges = db.clip_ranges[db.frame_clip[clean]]
        ref = lambda: np.stack([np.maximum(ranges[:, 0], clean - 20), np.minimum(ranges[:, 1], clean + 21)], 1)  # noqa: E731
    result = refused_or_equal(db.controller_windows, "frames", (frames,), ref)
    if kind in ("nonfinite", "value") or kind == "dtype" and np.asarray(frames).dtype.kind != "i":
        assert result is None or np.asarray(frames).dtype.kind in "iu"


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
        and clean.shape[1] == 3 and np.isfinite(clean).all() and len(clean) < HUGE else None
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
@given(case=hostile(np.array([0, 7, 6479], np.int64), values=[-1, 6480, -(2**63), 2**63 - 1]))
def test_database_global_positions_frames(db, case):
    _, frames = case
    refused_or_equal(lambda f: _core.database_global_positions(db._db, f), "frames", (frames,))
