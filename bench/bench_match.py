"""Batched motion-matching throughput (queries/s) on all shared data: our Matcher
(Database.match, 2 threads) vs numpy/BLAS brute force, scipy cKDTree(workers=-1) and faiss
IndexFlatL2, same rows (the valid frames), same queries, same run.

Query sets (noise in units of the per-dimension std of the normalized features):
  near    a database row + 0.05 std
  policy  frame i's pose part [0:15] with frame j's trajectory part [15:27], + 0.5 std
  far     frame i's pose part, trajectory part uniform in mean +- 3 std

Usage: python bench/bench_match.py [--data DIR] [--batches 64 4096] [--seconds 1.0]
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
    args = ap.parse_args()

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


if __name__ == "__main__":
    main()
