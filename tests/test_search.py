"""KDTree and Matcher against numpy brute force: random data, edge cases, bad inputs, and
real normalized features from ../shared (fails, never skips, under CI without the data)."""
import numpy as np
import pytest

import mmrl
from mmrl import _core
from mmrl.motion.search import KDTree


def numpy_knn(points, queries, k):
    """Reference in float64: (indices, squared distances), ties to the lower index."""
    d = ((queries[:, None, :].astype(np.float64) - points[None, :, :].astype(np.float64)) ** 2).sum(-1)
    order = np.lexsort((np.broadcast_to(np.arange(len(points)), d.shape), d), axis=-1)[:, :k]
    return order, np.take_along_axis(d, order, axis=1)


def assert_knn_matches(points, queries, idx, dist, k):
    ref_idx, ref_d = numpy_knn(points, queries, k)
    # Distances agree to float32 rounding; indices agree wherever the reference has no
    # near-tie (float32 vs float64 may order rows whose distances differ by an ulp).
    np.testing.assert_allclose(dist, ref_d, rtol=1e-5, atol=1e-5)
    true_d = ((queries[:, None, :].astype(np.float64) - points[idx].astype(np.float64)) ** 2).sum(-1)
    np.testing.assert_allclose(true_d, ref_d, rtol=1e-5, atol=1e-5)
    gaps = np.diff(np.concatenate([ref_d, np.full((len(ref_d), 1), np.inf)], axis=1), axis=1)
    clear = (gaps > 1e-4 * (1 + ref_d)) & np.concatenate(
        [np.ones((len(ref_d), 1), bool), gaps[:, :-1] > 1e-4 * (1 + ref_d[:, :-1])], axis=1)
    np.testing.assert_array_equal(idx[clear], ref_idx[clear])


@pytest.mark.parametrize("n", [1, 2, 17, 1000, 5000])
@pytest.mark.parametrize("dim", [1, 2, 5, 27])
def test_kdtree_equals_numpy_brute_force(n, dim):
    rng = np.random.default_rng(n * 100 + dim)
    points = rng.normal(size=(n, dim)).astype(np.float32)
    queries = np.concatenate([
        points[rng.integers(0, n, 20)] + 0.05 * rng.normal(size=(20, dim)),
        2.0 * rng.normal(size=(20, dim)),
    ]).astype(np.float32)
    for leaf_size in (1, 4, 16, 64):
        tree = KDTree(points, leaf_size=leaf_size)
        for k in (1, 3, 10):
            if k > n:
                continue
            idx, dist = tree.query(queries, k=k)
            assert idx.shape == (40, k) and idx.dtype == np.int64
            assert dist.shape == (40, k) and dist.dtype == np.float32
            assert_knn_matches(points, queries, idx, dist, k)


def test_kdtree_duplicates_tie_to_lowest_index():
    rng = np.random.default_rng(1)
    base = rng.normal(size=(5, 3)).astype(np.float32)
    points = base[rng.integers(0, 5, 400)]
    tree = KDTree(points, leaf_size=4)
    idx, dist = tree.query(base, k=3)
    for r in range(5):
        np.testing.assert_array_equal(idx[r], np.flatnonzero((points == base[r]).all(1))[:3])
        np.testing.assert_array_equal(dist[r], 0.0)


def test_empty_and_one_row_trees():
    empty = KDTree(np.zeros((0, 4), np.float32))
    idx, dist = empty.query(np.zeros((2, 4), np.float32))
    np.testing.assert_array_equal(idx, -1)
    assert np.isinf(dist).all()
    with pytest.raises(ValueError, match="k"):
        empty.query(np.zeros((1, 4), np.float32), k=2)
    one = KDTree(np.array([[1.0, 2.0]], np.float32))
    idx, dist = one.query(np.array([[0.0, 0.0], [1.0, 2.0]], np.float32))
    np.testing.assert_array_equal(idx, [[0], [0]])
    np.testing.assert_array_equal(dist, [[5.0], [0.0]])
    idx, dist = one.query(np.zeros((0, 2), np.float32))
    assert idx.shape == (0, 1)


def test_kdtree_threads_do_not_change_the_results():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(3000, 27)).astype(np.float32)
    queries = (points[rng.integers(0, 3000, 500)] + 0.5 * rng.normal(size=(500, 27))).astype(np.float32)
    serial = KDTree(points, num_threads=1)
    assert serial.num_threads == 1 and KDTree(points, num_threads=2).num_threads == 2
    for k in (1, 5):
        idx, dist = serial.query(queries, k=k)
        assert_knn_matches(points, queries, idx, dist, k)
        for threads in (2, 3, 0):
            other_idx, other_dist = KDTree(points, num_threads=threads).query(queries, k=k)
            np.testing.assert_array_equal(other_idx, idx)
            np.testing.assert_array_equal(other_dist, dist)  # bit for bit


def test_kdtree_keeps_points_alive():
    tree = KDTree(np.arange(12, dtype=np.float32).reshape(6, 2))
    import gc

    gc.collect()
    idx, dist = tree.query(np.array([[4.0, 5.0]], np.float32))
    assert idx[0, 0] == 2 and dist[0, 0] == 0.0


@pytest.mark.parametrize("bad, exc, word", [
    (lambda: KDTree(np.zeros((5, 3), np.float64)), TypeError, "points"),
    (lambda: KDTree([[0.0, 1.0]]), TypeError, "points"),
    (lambda: KDTree(np.zeros(5, np.float32)), ValueError, "points"),
    (lambda: KDTree(np.zeros((5, 0), np.float32)), ValueError, "points"),
    (lambda: KDTree(np.zeros((5, 3), np.float32)[:, ::2].copy().T), ValueError, None),
    (lambda: KDTree(np.zeros((6, 4), np.float32)[:, ::2]), ValueError, "contiguous"),
    (lambda: KDTree(np.full((5, 3), np.nan, np.float32)), ValueError, "NaN"),
    (lambda: KDTree(np.zeros((5, 3), np.float32), leaf_size=0), ValueError, "leaf_size"),
    (lambda: KDTree(np.zeros((5, 3), np.float32), num_threads=-1), ValueError, "num_threads"),
])
def test_kdtree_refuses_bad_construction(bad, exc, word):
    with pytest.raises(exc, match=word):
        bad()


def test_kdtree_refuses_bad_queries():
    tree = KDTree(np.zeros((5, 3), np.float32))
    good = np.zeros((2, 3), np.float32)
    with pytest.raises(TypeError, match="queries"):
        tree.query(good.astype(np.float64))
    with pytest.raises(ValueError, match="queries"):
        tree.query(np.zeros((2, 4), np.float32))
    with pytest.raises(ValueError, match="queries"):
        tree.query(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="queries.*NaN"):
        tree.query(np.array([[0, np.nan, 0]], np.float32))
    for k in (0, -1, 6):
        with pytest.raises(ValueError, match="k"):
            tree.query(good, k=k)


# ------------------------------------------------------------------ Matcher (motion matching)
def numpy_match(points, valid, queries, bounds=None):
    """Reference: nearest valid row; a bound row keeps its place unless strictly beaten."""
    d = ((queries[:, None, :].astype(np.float64) - points[None, :, :].astype(np.float64)) ** 2).sum(-1)
    d[:, ~valid.astype(bool)] = np.inf
    idx = d.argmin(1)
    cost = d[np.arange(len(d)), idx]
    idx[np.isinf(cost)] = -1
    if bounds is not None:
        bd = ((queries.astype(np.float64) - points[np.maximum(bounds, 0)]) ** 2).sum(-1)
        keep = (bounds >= 0) & (bd <= cost)
        idx[keep] = bounds[keep]
        cost[keep] = bd[keep]
    return idx, cost


def check_matcher(points, valid, queries, bounds=None, num_threads=2):
    m = _core.Matcher(points, valid, num_threads=num_threads)
    idx, cost = m.match(queries, bounds)
    bidx, bcost = m.brute_force(queries, bounds)
    np.testing.assert_array_equal(idx, bidx)  # the exact C++ reference, bit for bit
    np.testing.assert_array_equal(cost, bcost)
    ridx, rcost = numpy_match(points, valid, queries, bounds)
    np.testing.assert_allclose(cost, rcost, rtol=1e-5, atol=1e-5)
    assert (idx == ridx).mean() > 0.99  # ulp-level near-ties may order differently in float64
    ok = idx >= 0
    assert valid[idx[ok]].all() or bounds is not None
    return idx, cost


@pytest.mark.parametrize("n", [2, 17, 3000])
def test_matcher_equals_brute_force_random(n):
    rng = np.random.default_rng(n)
    points = rng.normal(size=(n, 27)).astype(np.float32)
    valid = rng.random(n) < 0.8
    rows = rng.integers(0, n, 64)
    queries = (points[rows] + 0.5 * rng.normal(size=(64, 27))).astype(np.float32)
    check_matcher(points, valid, queries)
    check_matcher(points, valid.astype(np.uint8), queries, np.where(rows % 3 == 0, -1, rows).astype(np.int64))
    check_matcher(points, valid, queries, num_threads=1)


def test_matcher_mask_excluding_everything():
    points = np.random.default_rng(0).normal(size=(50, 27)).astype(np.float32)
    m = _core.Matcher(points, np.zeros(50, np.uint8))
    idx, cost = m.match(points[:3])
    np.testing.assert_array_equal(idx, -1)
    assert np.isinf(cost).all()
    idx, cost = m.match(points[:3], np.array([4, -1, 7], np.int64))  # only the bound remains
    np.testing.assert_array_equal(idx, [4, -1, 7])
    empty = _core.Matcher(np.zeros((0, 27), np.float32), np.zeros(0, bool))
    assert empty.match(points[:2])[0].tolist() == [-1, -1]


def test_matcher_refuses_bad_input():
    points = np.zeros((10, 27), np.float32)
    with pytest.raises(TypeError, match="valid_mask"):
        _core.Matcher(points, np.ones(10, np.int32))
    with pytest.raises(ValueError, match="valid_mask"):
        _core.Matcher(points, np.ones(9, np.uint8))
    with pytest.raises(TypeError, match="points"):
        _core.Matcher(points.astype(np.float64), np.ones(10, np.uint8))
    with pytest.raises(ValueError, match="num_threads"):
        _core.Matcher(points, np.ones(10, np.uint8), num_threads=-1)
    m = _core.Matcher(points, np.ones(10, np.uint8))
    with pytest.raises(ValueError, match="queries"):
        m.match(np.zeros((2, 26), np.float32))
    with pytest.raises(ValueError, match="queries.*NaN"):
        m.match(np.full((2, 27), np.inf, np.float32))
    with pytest.raises(TypeError, match="bound_indices"):
        m.match(np.zeros((2, 27), np.float32), np.zeros(2, np.int32))
    with pytest.raises(ValueError, match="bound_indices"):
        m.match(np.zeros((2, 27), np.float32), np.zeros(3, np.int64))
    with pytest.raises(ValueError, match="bound_indices"):
        m.match(np.zeros((2, 27), np.float32), np.array([0, 10], np.int64))


# ------------------------------------------------------------------ real features
def policy_like_queries(x, rng, m, noise):
    """A frame's pose part [0:15] with another frame's trajectory part [15:27], plus noise
    in units of the per-dimension std of the normalized features."""
    std = x.std(0)
    i, j = rng.integers(0, len(x), m), rng.integers(0, len(x), m)
    q = np.concatenate([x[i, :15], x[j, 15:]], axis=1)
    return (q + noise * std * rng.normal(size=q.shape)).astype(np.float32), i


@pytest.fixture(scope="module")
def normal_style_db(shared_data):
    return mmrl.Database.from_bvh(shared_data / "normal")


def test_real_features_kdtree_and_matcher(normal_style_db):
    x = np.ascontiguousarray(normal_style_db.normalized_features)
    valid = normal_style_db.valid_mask
    rng = np.random.default_rng(0)
    near = (x[rng.integers(0, len(x), 100)] + 0.05 * x.std(0) * rng.normal(size=(100, 27))).astype(np.float32)
    policy, frames = policy_like_queries(x, rng, 100, 0.5)
    lo, hi = x.mean(0) - 3 * x.std(0), x.mean(0) + 3 * x.std(0)
    far = policy.copy()
    far[:, 15:] = rng.uniform(lo[15:], hi[15:], size=(100, 12))
    sub = x[:4000]  # numpy's float64 reference over a slice keeps this fast
    tree = KDTree(np.ascontiguousarray(sub), leaf_size=16)
    for queries in (near, policy, far):
        idx, dist = tree.query(queries, k=3)
        assert_knn_matches(sub, queries, idx, dist, 3)
        bounds = np.minimum(frames + 1, len(x) - 1).astype(np.int64)
        check_matcher(x, valid, queries)
        check_matcher(x, valid, queries, bounds)


def test_database_match_uses_matcher(normal_style_db):
    db = normal_style_db
    x = np.ascontiguousarray(db.normalized_features)
    queries, frames = policy_like_queries(x, np.random.default_rng(1), 50, 0.5)
    idx, cost = db.match(queries, normalized=True)
    bidx, bcost = db.matcher.brute_force(queries)
    np.testing.assert_array_equal(idx, bidx)
    np.testing.assert_array_equal(cost, bcost)
    assert db.valid_mask[idx].all()
