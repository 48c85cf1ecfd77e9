"""Clip costs: a spec ``"PATTERN=COST;..."`` over a database's clip names, as the per-clip
costs the C++ ``ClipCostFilter`` adds to candidates (task option ``clip_costs``)."""
from __future__ import annotations

import fnmatch
import os

import numpy as np

from .database import Database


def _clip_matches(name: str, pattern: str) -> bool:
    """A clip's name (its BVH path, for clips read from files) matches a pattern by the whole
    name, its file name or its file name without the extension."""
    base = os.path.basename(name)
    return any(fnmatch.fnmatchcase(n, pattern) for n in (name, base, os.path.splitext(base)[0]))


def clip_cost_array(spec: str, db: Database, option: str = "clip_costs") -> np.ndarray:
    """The per-clip costs (float32, one per clip of ``db``) of a clip-cost spec
    ``"PATTERN=COST;PATTERN=COST"``: each PATTERN a shell-style pattern (``fnmatch``) of clip
    names, matched against the whole name, the file name or the file name without its
    extension (``run_*``, ``*turn*``, ``dataset/style/*.bvh``), each COST >= 0 in squared normalized feature distance, or ``inf`` (never
    play those clips). Costs of patterns that match the same clip add up. A malformed item, or
    a pattern that matches no clip, raises ValueError naming ``option``. The C++ rule that
    applies them is ``ClipCostFilter`` (cpp/include/mmrl/decision.hpp)."""
    if not isinstance(db, Database):
        raise ValueError(f"{option}: needs the database to resolve clip names")
    names = list(db.clip_names)
    costs = np.zeros(len(names), np.float64)
    for item in (part.strip() for part in str(spec).split(";")):
        if not item:
            continue
        pattern, sep, value = item.rpartition("=")
        pattern = pattern.strip()
        try:
            cost = float(value)
        except ValueError:
            cost = float("nan")
        if not sep or not pattern or not cost >= 0:
            raise ValueError(f"{option}: expected PATTERN=COST with COST >= 0 or inf, got {item!r}")
        hits = [k for k, n in enumerate(names) if _clip_matches(n, pattern)]
        if not hits:
            raise ValueError(f"{option}: pattern {pattern!r} matches no clip of the database (clips look like "
                             f"{names[0]!r})")
        costs[hits] += cost
    return costs.astype(np.float32)
