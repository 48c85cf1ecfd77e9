"""What kinds of motion a database holds: the share of its valid frames that stand, turn in
place, step sideways or step backwards, read from each frame's own +30-frame trajectory sample
(its displacement and heading one second ahead at 30 fps, in the character frame: X left, Z
forward). ``mmrl db info`` prints them; a task that needs a kind (the arrive task: standing)
refuses data without it before training (docs/arrive.md).

- idle: moves less than ``IDLE_METERS`` (0.15 m) over the next second;
- turn in place: turns more than 60 degrees while moving less than 0.5 m;
- sideways: moves at least 0.15 m, more to the side than forward or back;
- backwards: moves at least 0.15 m, more backward than to the side.
"""
from __future__ import annotations

from typing import Dict

import numpy as np

from .. import _core
from .database import Database

IDLE_METERS = _core.IDLE_METERS  # features.hpp's kIdleMeters, the arrive stand's measure too
TURN_IN_PLACE_DEGREES, TURN_IN_PLACE_METERS = 60.0, 0.5
#: The share of idle frames below which a database "cannot stop" (the arrive task refuses it).
MIN_IDLE_SHARE = 0.005


def motion_kinds(db: Database) -> Dict[str, float]:
    """The share (0..1) of the valid frames of each kind (the module docstring)."""
    f = db.features[db.valid_mask].astype(np.float64)
    if f.shape[0] == 0:
        return {"idle": 0.0, "turn_in_place": 0.0, "sideways": 0.0, "backwards": 0.0}
    p, d = _core.TRAJECTORY_POSITION_COLUMNS[2], _core.TRAJECTORY_DIRECTION_COLUMNS[2]
    x, z = f[:, p], f[:, p + 1]
    dist = np.hypot(x, z)
    turn = np.degrees(np.abs(np.arctan2(f[:, d], f[:, d + 1])))
    moving = dist >= IDLE_METERS
    return {"idle": float(np.mean(dist < IDLE_METERS)),
            "turn_in_place": float(np.mean((turn > TURN_IN_PLACE_DEGREES) & (dist < TURN_IN_PLACE_METERS))),
            "sideways": float(np.mean(moving & (np.abs(x) > np.abs(z)))),
            "backwards": float(np.mean(moving & (z < -np.abs(x))))}


def idle_frames(db: Database) -> np.ndarray:
    """(num_frames,) bool: the valid frames that stand (move less than ``IDLE_METERS`` over the
    next second)."""
    f = np.asarray(db.features, np.float64)
    p = _core.TRAJECTORY_POSITION_COLUMNS[2]
    return np.asarray(db.valid_mask, bool) & (np.hypot(f[:, p], f[:, p + 1]) < IDLE_METERS)


def kinds_line(db: Database) -> str:
    """``mmrl db info``'s line of motion kinds."""
    k = motion_kinds(db)
    return (f"motion       of the valid frames: {100 * k['idle']:.1f}% idle, {100 * k['turn_in_place']:.1f}% turning "
            f"in place, {100 * k['sideways']:.1f}% sideways, {100 * k['backwards']:.1f}% backwards "
            f"(over the next second; docs/arrive.md)")


def check_can_stop(db: Database) -> None:
    """ValueError saying what is missing when the database barely stands (arrive task)."""
    idle = motion_kinds(db)["idle"]
    if idle < MIN_IDLE_SHARE:
        raise ValueError(
            f"the data cannot stop: {100 * idle:.2f}% of its valid frames stand still (move < {IDLE_METERS} m over "
            f"the next second; at least {100 * MIN_IDLE_SHARE:.1f}% needed), so no policy can arrive and rest. "
            "Add clips with stops, idles and turns in place (LAFAN1's walks have them; docs/arrive.md)")


__all__ = ["IDLE_METERS", "MIN_IDLE_SHARE", "check_can_stop", "idle_frames", "kinds_line", "motion_kinds"]
