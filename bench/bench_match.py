"""Batched motion-matching throughput (queries/s) on all shared data: our Matcher
(Database.match, 2 threads) vs numpy/BLAS brute force, scipy cKDTree(workers=-1) and faiss
IndexFlatL2, same rows (the valid frames), same queries, same run.

Query sets (noise in units of the per-dimension std of the normalized features):
  near    a database row + 0.05 std
  policy  frame i's pose part [0:15] with frame j's trajectory part [15:27], + 0.5 std
  far     frame i's pose part, trajectory part uniform in mean +- 3 std

Usage: python bench/bench_match.py [--data DIR] [--batches 64 4096] [--seconds 1.0]

--knn: the public k-NN instead, mmrl.KDTree.query (k=1) vs numpy/BLAS brute force and scipy
cKDTree, over all rows of the database's normalized features standardized per
column (mean 0, std 1). 4,096 policy-like queries: frame i's pose part [0:15] with frame j's
trajectory part [15:27] + 0.5 std of noise. The database is built once and cached
(--db-cache, an .npz under /tmp by default; --rebuild to build it again). --threads sets the
threads of KDTree and cKDTree; BLAS takes its own from the environment (OPENBLAS_NUM_THREADS=1
with --threads 1 compares one core each, less disturbed by other work on the machine).

       python bench/bench_match.py --knn [--data DIR] [--db-cache FILE.npz] [--queries 4096]
"""
import argparse
import os
import time
from pathlib import Path

import numpy as np

import mmrl

DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "bandai-namco-2"


def make_queries(x, rng, m):
    std, mean = x.std(0), x.mean(0)
    i, j = rng.integers(0, len(x) - 1, m), rng.integers(0, len(x) - 1, m)
    near = x[i] + 0.05 * std * rng.normal(size=(m, 27))
    policy = np.concatenate([x[i, :15], x[j, 15:]], 1) + 0.5 * std * rng.normal(size=(m, 27))
    far = x[i].copy()
    far[:, 15:] = mean[15:] + rng.uniform(-3, 3, size=(m, 12)) * std[15:]
    as32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return {"near": as32(near), "policy": as32(policy), "far": as32(far)}, (i + 1).astype(np.int64)


def throughput(fn, queries, batch, seconds):
    """Queries/s of fn over consecutive batches, at least one batch and `seconds` of work."""
    fn(queries[:batch])  # warm-up
    done, start, k = 0, time.perf_counter(), 0
    while True:
        lo = (k * batch) % (len(queries) - batch + 1)
        fn(queries[lo:lo + batch])
        done += batch
        k += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return done / elapsed


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--batches", type=int, nargs="+", default=[64, 4096])
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--knn", action="store_true", help="benchmark mmrl.KDTree.query instead (see above)")
    ap.add_argument("--db-cache", type=Path, default=None,
                    help="--knn: the database .npz cache (default /tmp/mmrl-bench-match-<data dir name>.npz)")
    ap.add_argument("--rebuild", action="store_true", help="--knn: build the cached database again")
    ap.add_argument("--queries", type=int, default=4096, help="--knn: number of queries, all in one batch")
    args = ap.parse_args()
    if args.knn:
        return knn_main(args)

    import faiss
    from scipy.spatial import cKDTree

    faiss.omp_set_num_threads(args.threads)
    db = mmrl.Database.from_bvh(args.data)
    x = np.ascontiguousarray(db.normalized_features)
    valid_rows = np.flatnonzero(db.valid_mask)
    xv = np.ascontiguousarray(x[valid_rows])
    xv_sq = (xv.astype(np.float32) ** 2).sum(1)
    print(f"{len(x)} rows, {len(xv)} valid, {args.threads} threads")

    sets, bounds = make_queries(x, np.random.default_rng(0), 8192)
    matcher = db.matcher
    ckd = cKDTree(xv)
    flat = faiss.IndexFlatL2(27)
    flat.add(xv)

    def numpy_brute(q):  # |q|^2 - 2 q.x + |x|^2 through BLAS, per batch
        d = xv_sq[None, :] - 2.0 * (q @ xv.T)
        return valid_rows[d.argmin(1)]

    peers = {
        "ours": lambda q: matcher.match(q)[0],
        "numpy": numpy_brute,
        "cKDTree": lambda q: valid_rows[ckd.query(q, k=1, workers=-1)[1]],
        "faiss": lambda q: valid_rows[flat.search(q, 1)[1][:, 0]],
    }
    # Same answers (up to float near-ties between different distance formulas).
    for name, q in sets.items():
        ref = matcher.brute_force(q[:256])[0]
        for peer, fn in peers.items():
            agree = (fn(q[:256]) == ref).mean()
            if agree < 0.99:
                print(f"warning: {peer} agrees with brute force on {agree:.1%} of {name} queries")

    rows = []
    for batch in args.batches:
        for name, q in sets.items():
            r = {p: throughput(fn, q, batch, args.seconds) for p, fn in peers.items()}
            r["ours+bound"] = throughput(lambda qq: matcher.match(qq, bounds[:len(qq)])[0], q, batch, args.seconds)
            rows.append((batch, name, r))
            print(f"batch {batch:5d} {name:7s} " + "  ".join(f"{p} {v:10.0f}/s" for p, v in r.items()), flush=True)

    print("\n| batch | queries | ours (q/s) | ours+bound | numpy/BLAS | x | cKDTree | x | faiss flat | x |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for batch, name, r in rows:
        o = r["ours"]
        print(f"| {batch} | {name} | {o:,.0f} | {r['ours+bound']:,.0f} | {r['numpy']:,.0f} | {o / r['numpy']:.1f} | "
              f"{r['cKDTree']:,.0f} | {o / r['cKDTree']:.0f} | {r['faiss']:,.0f} | {o / r['faiss']:.1f} |")


def cached_database(data, cache, rebuild):
    """The database of `data`, built once and saved to `cache` (building all shared data takes a while)."""
    if cache.is_file() and not rebuild:
        return mmrl.Database.load(cache)
    db = mmrl.Database.from_bvh(data)
    db.save(cache)
    return db


def knn_main(args):
    from scipy.spatial import cKDTree

    cache = args.db_cache or Path("/tmp") / f"mmrl-bench-match-{args.data.name}.npz"
    db = cached_database(args.data, cache, args.rebuild)
    x = np.asarray(db.normalized_features, dtype=np.float64)
    std = x.std(0)
    x = np.ascontiguousarray((x - x.mean(0)) / np.where(std > 0, std, 1.0), dtype=np.float32)
    x_sq = (x.astype(np.float64) ** 2).sum(1).astype(np.float32)

    rng = np.random.default_rng(0)
    m = args.queries
    i, j = rng.integers(0, len(x), m), rng.integers(0, len(x), m)
    queries = np.concatenate([x[i, :15], x[j, 15:] + 0.5 * rng.normal(size=(m, 12))], 1)
    queries = np.ascontiguousarray(queries, dtype=np.float32)
    print(f"mmrl {mmrl.__file__}\n{len(x)} rows x {x.shape[1]}, {m} queries, {args.threads} threads "
          f"(database cache {cache})")

    tree = mmrl.KDTree(x, leaf_size=16, num_threads=args.threads)
    ckd = cKDTree(x)

    def numpy_brute(q, query_chunk=256, row_chunk=16384):
        """argmin of |q|^2 - 2 q.x + |x|^2, the products through BLAS, in chunks of both."""
        best = np.empty(len(q), np.int64)
        for a in range(0, len(q), query_chunk):
            qc = q[a:a + query_chunk]
            best_d = np.full(len(qc), np.inf, np.float32)
            best_i = np.zeros(len(qc), np.int64)
            q_sq = (qc * qc).sum(1)
            for b in range(0, len(x), row_chunk):
                d = q_sq[:, None] - 2.0 * (qc @ x[b:b + row_chunk].T) + x_sq[None, b:b + row_chunk]
                arg = d.argmin(1)
                dmin = d[np.arange(len(qc)), arg]
                better = dmin < best_d
                best_d[better], best_i[better] = dmin[better], arg[better] + b
            best[a:a + query_chunk] = best_i
        return best

    peers = {
        "KDTree.query": lambda q: tree.query(q, k=1)[0][:, 0],
        "numpy/BLAS": numpy_brute,
        "cKDTree": lambda q: ckd.query(q, k=1, workers=args.threads)[1],
    }
    ref = peers["KDTree.query"](queries)
    for peer, fn in peers.items():  # the same answers, up to float near-ties of other formulas
        agree = (fn(queries) == ref).mean()
        if agree < 0.99:
            print(f"warning: {peer} agrees with KDTree.query on {agree:.1%} of the queries")
    rates = {p: throughput(fn, queries, m, args.seconds) for p, fn in peers.items()}
    base = rates["numpy/BLAS"]
    for p, r in rates.items():
        print(f"{p:14s} {r:10,.0f} q/s  {r / base:5.2f}x numpy/BLAS")


if __name__ == "__main__":
    main()
