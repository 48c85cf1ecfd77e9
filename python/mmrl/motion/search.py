"""Exact nearest-neighbour search over feature rows (thin layer over the C++ core).

:class:`KDTree` is the general k-NN index. Motion matching itself goes through
:meth:`mmrl.Database.match`, which uses ``mmrl._core.Matcher`` (the same tree, restricted to
valid frames, with the current frame's continuation as a bound, batched over threads).
"""
from __future__ import annotations

from typing import Tuple

import numpy as np

from .. import _core


class KDTree:
    """Exact k-nearest-neighbour KD-tree, squared Euclidean distance, float32.

    The tree borrows ``points`` (it keeps a reference, so do not modify the array in place
    afterwards) and stores a permuted, blocked copy of the rows in its leaves for fast scans.
    Nodes hold tight bounding boxes; results equal a brute-force scan exactly, with ties
    going to the lower row index.

    Args:
        points: (N, D) float32, C-contiguous, finite; 1 <= D <= 128. N may be 0.
        leaf_size: rows per leaf (>= 1). 16 is a good default for 27-d motion features.
        num_threads: threads that answer a batch of queries, the caller's included
            (0 = all cores, 1 = the caller only). Results do not depend on it.

    Raises:
        TypeError: ``points`` is not a float32 numpy array.
        ValueError: wrong shape, non-contiguous, NaN/inf, leaf_size < 1 or num_threads < 0.
    """

    def __init__(self, points: np.ndarray, leaf_size: int = 16, num_threads: int = 0):
        self._tree = _core.KDTree(points, leaf_size=leaf_size, num_threads=num_threads)

    def query(self, queries: np.ndarray, k: int = 1) -> Tuple[np.ndarray, np.ndarray]:
        """The k nearest rows of each query.

        Args:
            queries: (M, D) float32, C-contiguous, finite.
            k: neighbours per query, 1 <= k <= N (an empty tree accepts k = 1).

        Returns:
            (indices int64 (M, k), squared_distances float32 (M, k)), nearest first. An
            empty tree returns index -1 and distance inf.
        """
        return self._tree.query(queries, k)

    size = property(lambda self: self._tree.size, doc="Number of rows (N).")
    dim = property(lambda self: self._tree.dim, doc="Row dimension (D).")
    leaf_size = property(lambda self: self._tree.leaf_size, doc="Rows per leaf.")
    num_threads = property(lambda self: self._tree.num_threads,
                           doc="Threads that answer a batch of queries (the caller's included).")

    def __repr__(self) -> str:
        return f"KDTree(size={self.size}, dim={self.dim}, leaf_size={self.leaf_size})"
