"""Rendering (placeholder top-down view until the full renderer lands)."""
from __future__ import annotations

import numpy as np


def render_topdown(states, size: int = 256, extent: float = 8.0) -> np.ndarray:
    """A simple top-down RGB image of characters (dots and headings) and their targets."""
    img = np.full((size, size, 3), 235, np.uint8)
    def px(x, z):
        return int(size / 2 - x / extent * size / 2), int(size / 2 - z / extent * size / 2)
    for s in states:
        tx, tz = s["target"]
        u, v = px(tx, tz)
        img[max(0, v - 3):v + 4, max(0, u - 3):u + 4] = (220, 40, 40)
        u, v = px(s["x"], s["z"])
        img[max(0, v - 3):v + 4, max(0, u - 3):u + 4] = (40, 40, 200)
    return img
