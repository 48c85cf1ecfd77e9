"""Checks of a user's data that a database build and load make: a file that is BVH or a
database whatever its name, the file unit, and data that cannot be matched or moves at no
person's speed (a wrong unit)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Union

import numpy as np

from .. import _core
from ..errors import InputError
from .bvh import MotionImportWarning

PathLike = Union[str, os.PathLike]

#: Median speeds (m/s, over the valid frames, from the +1 s trajectory sample) outside this
#: range are not people moving: a wrong unit (``--scale``) is the usual cause.
PLAUSIBLE_MEDIAN_SPEED = (0.05, 8.0)
_UNITS = {1.0: "meters", 0.01: "centimeters", 0.0254: "inches", 0.001: "millimeters"}


def unit_name(scale: float) -> str:
    """The unit a file scale (file units -> meters) stands for, e.g. ``"centimeters"``."""
    for s, name in _UNITS.items():
        if abs(scale - s) <= 1e-6 * s:
            return name
    return f"{scale:g} m per unit"


def is_bvh_file(path: Path) -> bool:
    """A file that starts like BVH text (``HIERARCHY``), whatever its name."""
    with open(path, "rb") as fh:
        return fh.read(64).lstrip(b"\xef\xbb\xbf \t\r\n").upper().startswith(b"HIERARCHY")


def is_database_file(path: PathLike) -> bool:
    """A file that starts like an ``.npz`` (a zip), whatever its name."""
    try:
        with open(path, "rb") as fh:
            return fh.read(4) == b"PK\x03\x04"
    except OSError:
        return False


def check_usable(core, motions) -> None:
    """InputError when no frame can be matched; MotionImportWarning when the data's median speed
    is not a person's (a wrong unit)."""
    valid = core.valid_mask.view(np.bool_)
    if not valid.any():
        need = int(_core.TRAJECTORY_OFFSETS[-1]) + 1
        longest = max((m.num_frames for m in motions), default=0)
        raise InputError(f"no clip is long enough to match: a clip needs more than {need} frames "
                         f"({need / core.fps:.2f} s at {core.fps:g} fps) and the longest of the {len(motions)} "
                         f"has {longest}; add longer clips")
    col = _core.TRAJECTORY_POSITION_COLUMNS[2]
    f = core.features[valid]
    speed = float(np.median(np.hypot(f[:, col], f[:, col + 1]))) * core.fps / _core.TRAJECTORY_OFFSETS[-1]
    lo, hi = PLAUSIBLE_MEDIAN_SPEED
    if not lo <= speed <= hi:
        import warnings

        scale = float(core.source_scale)
        # The unit that would give a walking median (about 1.3 m/s), on a log scale.
        guess = min(_UNITS, key=lambda u: abs(np.log(u / (scale * 1.3 / max(speed, 1e-9)))))
        warnings.warn(f"the data's median speed is {speed:.3g} m/s, not a person's ({lo:g}-{hi:g} m/s): is the unit "
                      f"right? The scale is {scale:g} ({unit_name(scale)}); if the files are in {_UNITS[guess]}, "
                      f"pass --scale {guess:g} (scale={guess:g} from Python)", MotionImportWarning, stacklevel=4)
