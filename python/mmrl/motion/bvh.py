"""BVH import and export.

``load_bvh`` parses any channel layout (3 or 6 channels, any rotation order, End Sites,
tabs, CRLF, blank lines) in C++ and returns a :class:`Motion` in meters, Y up: a Z-up file
is rotated to Y up (detected, or given by ``up``), and ``fps`` resamples the clip
(positions linear, rotations slerp). ``load_bvh`` then warns (:class:`MotionImportWarning`)
when the result does not look like a person moving over a floor.
"""
from __future__ import annotations

import os
import warnings
from typing import List, Optional

from .. import _core

BVHError = _core.BVHError
JointRoleError = _core.JointRoleError
Motion = _core.Motion

#: A skeleton shorter than this fraction of its horizontal extent lies flat (m / m).
FLAT_HEIGHT_RATIO = 0.5
#: A centre of mass rising or falling more than this (m), farther than it moves over the
#: ground, is a clip read with the wrong up axis (running straight up).
MAX_VERTICAL_TRAVEL_M = 1.0


class MotionImportWarning(UserWarning):
    """An imported clip looks implausible (lying flat, travelling vertically)."""


def _options(scale: Optional[float], up: Optional[str], fps: Optional[float]):
    if scale is not None and not (scale > 0):
        raise ValueError(f"scale must be positive, got {scale!r}")
    if up is not None and (not isinstance(up, str) or up.lower() not in ("y", "z", "auto")):
        raise ValueError(f"up must be 'y', 'z' or None (detect), got {up!r}")
    if fps is not None and not (fps > 0 and fps < float("inf")):
        raise ValueError(f"fps must be positive, got {fps!r}")
    return float(scale or 0.0), (up or "auto").lower(), float(fps or 0.0)


def check_motion(motion: Motion) -> List[str]:
    """Reasons an imported motion does not look like a person moving over a floor (empty
    when it does): the skeleton lying flat (median height below ``FLAT_HEIGHT_RATIO`` of its
    horizontal extent), or its centre travelling more than ``MAX_VERTICAL_TRAVEL_M``
    vertically and farther vertically than horizontally (a run along the wrong up axis
    reads as a median ground speed near zero)."""
    p = motion.plausibility()
    problems = []
    if p["height"] < FLAT_HEIGHT_RATIO * p["horizontal_extent"]:
        problems.append(f"the skeleton lies flat: {p['height']:.2f} m tall but {p['horizontal_extent']:.2f} m "
                        f"across (medians over its frames)")
    if p["vertical_travel"] > MAX_VERTICAL_TRAVEL_M and p["horizontal_path"] < p["vertical_travel"]:
        problems.append(f"its centre travels {p['vertical_travel']:.1f} m vertically but {p['horizontal_path']:.1f} m "
                        f"over the ground in {p['seconds']:.1f} s (median ground speed "
                        f"{p['median_horizontal_speed']:.2f} m/s)")
    return problems


def warn_if_implausible(motion: Motion, problems: List[str], stacklevel: int = 2) -> None:
    """Emit one :class:`MotionImportWarning` naming the file, if ``problems`` is not empty."""
    if problems:
        warnings.warn(f"{motion.source}: implausible motion after import as {motion.up_axis.upper()} up: "
                      f"{'; '.join(problems)}. If the file's up axis is another one, pass up='y' or up='z' "
                      f"(mmrl db build --up).", MotionImportWarning, stacklevel=stacklevel + 1)


def load_bvh(path: "str | os.PathLike[str]", scale: Optional[float] = None, *, up: Optional[str] = None,
             fps: Optional[float] = None) -> Motion:
    """Load a BVH file.

    Args:
        path: the file.
        scale: file units to meters. ``None`` infers it: the skeleton's height in the first
            frame (its highest joint or End Site above the floor y = 0, or above its lowest
            point if that is below the floor) is matched to 1.5 m on a log scale among
            meters, centimeters, inches and millimeters.
        up: the file's up axis, ``"y"`` or ``"z"``; ``None`` detects it from the direction
            feet -> hips (joints found by name; Y when they are not found). A Z-up world is
            rotated -90 degrees about X to Y up: (x, y, z) -> (x, z, -y).
        fps: resample to this many frames per second (translations linear, rotations
            slerp) when the file's rate differs; ``None`` keeps the file's rate.

    Returns:
        A :class:`Motion` with ``joint_names``, ``parents``, ``fps``, ``source_fps``,
        ``up_axis``, ``num_frames``, ``local_translations``, ``local_rotations`` (w, x, y, z)
        and ``global_positions()``.

    Raises:
        BVHError: (a ``ValueError``) naming the file and the line of the problem.

    Warns:
        MotionImportWarning: the motion looks implausible (see :func:`check_motion`).
    """
    s, u, f = _options(scale, up, fps)
    motion = _core.bvh_load(os.fspath(path), s, u, f)
    warn_if_implausible(motion, check_motion(motion))
    return motion


def parse_bvh(text: str, source: str = "<string>", scale: Optional[float] = None, *, up: Optional[str] = None,
              fps: Optional[float] = None) -> Motion:
    """Parse BVH text (see :func:`load_bvh`). Does not warn; see :func:`check_motion`."""
    s, u, f = _options(scale, up, fps)
    return _core.bvh_parse(text, source, s, u, f)
