"""Database build and load times on all of the shared data (issue 2's benchmark).

    python bench/bench_database.py [--data DIR] [--repeat 3]

Build: parse all 962 BVH files (C++, one thread per core) and compute features. Load: read
the saved .npz back (the file is in the page cache after the first read; the first load is
reported separately).
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import mmrl

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mirror", action="store_true")
    args = ap.parse_args()
    files = sorted(Path(args.data).rglob("*.bvh"))
    size_mb = sum(f.stat().st_size for f in files) / 1e6
    builds, loads = [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "db.npz"
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            db = mmrl.Database.from_bvh(args.data, mirror=args.mirror)
            builds.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        db.save(path)
        save = time.perf_counter() - t0
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            back = mmrl.Database.load(path)
            loads.append(time.perf_counter() - t0)
        file_mb = path.stat().st_size / 1e6
    print(f"{len(files)} files, {size_mb:.0f} MB of BVH text -> {db!r}; {os.cpu_count()} cores")
    print(f"build from BVH: median {statistics.median(builds):.2f} s (runs: {', '.join(f'{b:.2f}' for b in builds)})")
    print(f"save: {save:.2f} s, {file_mb:.0f} MB")
    print(f"load: median {statistics.median(loads):.3f} s (runs: {', '.join(f'{x:.3f}' for x in loads)}); "
          f"{back.num_frames} frames")


if __name__ == "__main__":
    main()
