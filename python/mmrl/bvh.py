"""BVH import and export.

``load_bvh`` parses any channel layout (3 or 6 channels, any rotation order, End Sites,
tabs, CRLF, blank lines) in C++ and returns a :class:`Motion` in meters, Y up.
"""
from __future__ import annotations

import os
from typing import Optional

from . import _core

BVHError = _core.BVHError
JointRoleError = _core.JointRoleError
Motion = _core.Motion


def load_bvh(path: "str | os.PathLike[str]", scale: Optional[float] = None) -> Motion:
    """Load a BVH file.

    Args:
        path: the file.
        scale: file units to meters. ``None`` infers it: the skeleton's height in the first
            frame (its highest joint or End Site above the floor y = 0, or above its lowest
            point if that is below the floor) is matched to 1.5 m on a log scale among
            meters, centimeters, inches and millimeters.

    Returns:
        A :class:`Motion` with ``joint_names``, ``parents``, ``fps``, ``num_frames``,
        ``local_translations``, ``local_rotations`` (w, x, y, z) and ``global_positions()``.

    Raises:
        BVHError: (a ``ValueError``) naming the file and the line of the problem.
    """
    if scale is not None and not (scale > 0):
        raise ValueError(f"scale must be positive, got {scale!r}")
    return _core.bvh_load(os.fspath(path), float(scale or 0.0))


def parse_bvh(text: str, source: str = "<string>", scale: Optional[float] = None) -> Motion:
    """Parse BVH text (see :func:`load_bvh`)."""
    if scale is not None and not (scale > 0):
        raise ValueError(f"scale must be positive, got {scale!r}")
    return _core.bvh_parse(text, source, float(scale or 0.0))
