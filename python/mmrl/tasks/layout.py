"""Observation layouts: each task's env publishes its observation segment by segment
(``env.observation_layout``: ((name, size), ...) in order, from the C++ task), and readers take a
segment by name ("pose", "goal", "maps", "request", ...), never by guessing from the length."""
from __future__ import annotations


def obs_segment(layout, name: str) -> slice:
    """The slice of segment ``name`` in an observation of ``layout`` ((name, size), ...: an env's
    ``observation_layout``); KeyError naming the segments when it has none of that name."""
    start = 0
    for segment, size in layout:
        if segment == name:
            return slice(start, start + int(size))
        start += int(size)
    raise KeyError(f"the observation has no {name!r} segment (its segments: {', '.join(n for n, _ in layout)})")
