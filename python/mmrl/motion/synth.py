"""Procedural biped locomotion written as BVH files: the test data and the default database.

A small generator of walking, running, turning, starting, stopping, standing, side-stepping and
backward-walking clips at speeds from 0 to 4 m/s, in pure numpy and deterministic from a seed. Nothing is downloaded, so the unit
tests need no data and a user without motion capture still gets a working motion-matching
database (``default_dataset_dir()``).

How a clip is made (commands, gait, footholds, pelvis height, IK legs, upper body) is told and
done in :mod:`mmrl.motion.synth_motion`; this module writes the result as BVH and holds the public API.

Skeleton and file format
------------------------
Centimetres, Y up, the character faces +Z at yaw 0 and +X is its left. Joint names follow the
Bandai Namco convention (``Hips``, ``Spine``, ``Chest``, ``Neck``, ``Head``, ``Shoulder_L``,
``UpperArm_L``, ``LowerArm_L``, ``Hand_L``, ``UpperLeg_L``, ``LowerLeg_L``, ``Foot_L``,
``Toes_L`` and the ``_R`` copies). The rest pose (all rotations zero) is standing upright with
the arms hanging down. ``Hips`` is the root with 6 channels ``Xposition Yposition Zposition
Yrotation Xrotation Zrotation`` and a zero OFFSET (so adding the position channels to the offset
or replacing it gives the same result); every other joint has 3 channels ``Zrotation Yrotation
Xrotation``, i.e. local rotation = Rz * Ry * Rx, angles in degrees. Chains end in End Sites.

Public API
----------
- ``write_clip(path, *, speed, turn_rate=0.0, speed_end=None, direction=0.0, seconds=8.0, fps=30, seed=0)``
- ``write_dataset(out_dir, *, num_clips=None, seconds_per_clip=8.0, fps=30, seed=0)``
- ``default_dataset_dir()``
- ``JOINT_NAMES``, ``JOINT_PARENTS``, ``JOINT_OFFSETS_CM``, ``SYNTH_VERSION``
"""
from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..io import atomic_write_text
from .synth_motion import JOINT_NAMES, JOINT_OFFSETS_CM, JOINT_PARENTS, _SKELETON, _animate, _Clip, _draw_style

__all__ = [
    "JOINT_NAMES",
    "JOINT_PARENTS",
    "JOINT_OFFSETS_CM",
    "SYNTH_VERSION",
    "write_clip",
    "write_dataset",
    "default_dataset_dir",
]

# Bump when the generated motion changes, so cached default datasets are regenerated.
SYNTH_VERSION = 3  # 2: side steps and backward walks; 3: slow turns in place

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation")
_JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")  # local rotation = Rz * Ry * Rx


# ---------------------------------------------------------------------------------------------
# BVH writing
# ---------------------------------------------------------------------------------------------
def _euler_zyx_degrees(r: np.ndarray) -> np.ndarray:
    """Decompose rotation matrices (..., 3, 3) as Rz(a) Ry(b) Rx(c); returns (..., 3) = (a, b, c) in degrees."""
    b = np.arcsin(np.clip(-r[..., 2, 0], -1.0, 1.0))
    a = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    c = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    return np.degrees(np.stack([a, b, c], axis=-1))


def _hierarchy_text() -> str:
    children: Dict[int, List[int]] = {i: [] for i in range(len(JOINT_NAMES))}
    for j, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            children[p].append(j)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        keyword = "ROOT" if JOINT_PARENTS[j] < 0 else "JOINT"
        channels = _ROOT_CHANNELS if JOINT_PARENTS[j] < 0 else _JOINT_CHANNELS
        lines.append(f"{pad}{keyword} {JOINT_NAMES[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET " + " ".join(f"{x:.6f}" for x in JOINT_OFFSETS_CM[j]))
        lines.append(f"{pad}\tCHANNELS {len(channels)} " + " ".join(channels))
        for c in children[j]:
            emit(c, depth + 1)
        end_site = _SKELETON[j][3]
        if end_site is not None:
            lines.append(f"{pad}\tEnd Site")
            lines.append(f"{pad}\t{{")
            lines.append(f"{pad}\t\tOFFSET " + " ".join(f"{x:.6f}" for x in end_site))
            lines.append(f"{pad}\t}}")
        lines.append(f"{pad}}}")

    emit(0, 0)
    return "\n".join(lines) + "\n"


def _channel_values(clip: _Clip) -> np.ndarray:
    """Frame rows in the hierarchy's depth-first channel order: (F, 6 + 3 * (J - 1))."""
    columns = [clip.root_position_cm, clip.root_yxz_degrees]
    order = _hierarchy_order()
    for j in order[1:]:
        columns.append(_euler_zyx_degrees(clip.local_rotations[:, j]))
    return np.concatenate(columns, axis=1)


def _hierarchy_order() -> List[int]:
    order: List[int] = []

    def visit(j: int) -> None:
        order.append(j)
        for c, p in enumerate(JOINT_PARENTS):
            if p == j:
                visit(c)

    visit(0)
    return order


def _bvh_text(clip: _Clip, fps: float) -> str:
    values = _channel_values(clip)
    buf = io.StringIO()
    buf.write(_hierarchy_text())
    buf.write("MOTION\n")
    buf.write(f"Frames: {len(values)}\n")
    buf.write(f"Frame Time: {1.0 / fps:.8f}\n")
    values = np.where(np.abs(values) < 5e-7, 0.0, values)  # no "-0.000000"
    np.savetxt(buf, values, fmt="%.6f", delimiter=" ")
    return buf.getvalue()


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
_RAMP = (0.3, 0.7)  # speed changes ramp linearly between these fractions of the clip


def _check_args(seconds: float, fps: float) -> None:
    if not (np.isfinite(seconds) and seconds >= 1.0):
        raise ValueError(f"synth: seconds per clip must be >= 1, got {seconds!r}")
    if not (np.isfinite(fps) and 1.0 <= fps <= 1000.0):
        raise ValueError(f"synth: fps must be in [1, 1000], got {fps!r}")


def _check_command(speed: float, speed_end: float, turn_rate: float, direction: float = 0.0) -> None:
    for name, value in (("speed", speed), ("speed_end", speed_end)):
        if not (np.isfinite(value) and 0.0 <= value <= 4.5):
            raise ValueError(f"synth: {name} must be in [0, 4.5] m/s, got {value!r}")
    if not (np.isfinite(turn_rate) and abs(turn_rate) <= 3.0):
        raise ValueError(f"synth: turn_rate must be in [-3, 3] rad/s, got {turn_rate!r}")
    if not (np.isfinite(direction) and abs(direction) <= np.pi):
        raise ValueError(f"synth: direction must be in [-pi, pi] rad, got {direction!r}")


def _synthesize(speed: float, speed_end: float, turn_rate: float, direction: float, seconds: float, fps: float,
                rng: np.random.Generator) -> Tuple[_Clip, int]:
    num_frames = int(round(seconds * fps))
    pad = int(round(3.0 * fps))  # 3 s of lead-in and lead-out so the first and last steps are whole
    t = (np.arange(num_frames + 2 * pad) - pad) / fps
    duration = (num_frames - 1) / fps
    v = np.interp(t, [_RAMP[0] * duration, _RAMP[1] * duration], [speed, speed_end])
    w = np.full_like(t, turn_rate)
    style = _draw_style(rng)
    yaw0 = float(rng.uniform(-np.pi, np.pi))
    origin = rng.uniform(-5.0, 5.0, size=2)
    return _animate(v, w, float(fps), pad, yaw0, origin, style, direction), num_frames


def write_clip(path, *, speed: float, turn_rate: float = 0.0, speed_end: Optional[float] = None,
               direction: float = 0.0, seconds: float = 8.0, fps: float = 30, seed: int = 0) -> dict:
    """Write one synthetic clip to the BVH file `path` and return its description.

    speed: commanded ground speed in m/s (0 = standing or turning in place; up to 4.5).
    turn_rate: commanded yaw rate in rad/s, positive = turning left (counter-clockwise from above).
    speed_end: if given, the speed ramps linearly from `speed` to `speed_end` between 30% and 70%
        of the clip (a start, stop or speed change); otherwise the speed is constant.
    direction: the direction of travel from the facing in rad, + = left: 0 walks forward, pi/2
        steps sideways to the left, pi walks backwards (in [-pi, pi]).
    seconds, fps: clip length and frame rate. seed: gait style, start position and start heading.

    Returns a dict with the commanded values, the frame count, and the stance intervals of each
    foot (``contacts``: {"left": [[start, stop), ...], "right": ...} in frames), as stored in a
    dataset manifest. The same arguments always give the same bytes.
    """
    speed_end = float(speed if speed_end is None else speed_end)
    _check_args(seconds, fps)
    _check_command(float(speed), speed_end, float(turn_rate), float(direction))
    rng = np.random.default_rng(seed)
    clip, num_frames = _synthesize(float(speed), speed_end, float(turn_rate), float(direction), float(seconds),
                                   float(fps), rng)
    path = Path(path)
    atomic_write_text(path, _bvh_text(clip, fps))
    return {
        "file": path.name,
        "speed": float(speed),
        "speed_end": speed_end,
        "turn_rate": float(turn_rate),
        "direction": float(direction),
        "ramp_seconds": [r * (num_frames - 1) / fps for r in _RAMP] if speed_end != speed else None,
        "frames": num_frames,
        "fps": fps,
        "contacts": {k: [list(r) for r in v] for k, v in clip.contacts.items()},
    }


# The default plan: (kind, speed m/s, speed at the end m/s, turn rate rad/s). The first entries
# already cover walking, running and both turn directions, so small datasets stay varied.
_PLAN: Tuple[Tuple[str, float, float, float], ...] = (
    ("walk", 1.3, 1.3, 0.0),
    ("run", 3.0, 3.0, 0.0),
    ("walk-turn-left", 1.3, 1.3, 0.8),
    ("walk-turn-right", 1.3, 1.3, -0.8),
    ("run-turn-left", 3.0, 3.0, 0.6),
    ("run-turn-right", 3.0, 3.0, -0.6),
    ("speed-up", 1.3, 3.0, 0.0),
    ("slow-down", 3.0, 1.3, 0.0),
    ("stand", 0.0, 0.0, 0.0),
    ("walk", 0.5, 0.5, 0.0),
    ("walk", 0.9, 0.9, 0.0),
    ("walk", 1.8, 1.8, 0.0),
    ("run", 2.4, 2.4, 0.0),
    ("run", 3.5, 3.5, 0.0),
    ("run", 4.0, 4.0, 0.0),
    ("walk-turn-left", 1.0, 1.0, 1.5),
    ("walk-turn-right", 1.0, 1.0, -1.5),
    ("turn-in-place-left", 0.0, 0.0, 1.5),
    ("turn-in-place-right", 0.0, 0.0, -1.5),
    ("start", 0.0, 1.3, 0.0),
    ("stop", 1.3, 0.0, 0.0),
    ("walk-turn-left", 1.8, 1.8, 0.4),
    ("walk-turn-right", 1.8, 1.8, -0.4),
    ("run-turn-left", 2.4, 2.4, 1.0),
    ("run-turn-right", 2.4, 2.4, -1.0),
    ("speed-up", 0.5, 2.0, 0.0),
    ("slow-down", 4.0, 2.0, 0.0),
    ("step-left", 0.25, 0.25, 0.0),
    ("step-right", 0.25, 0.25, 0.0),
    ("walk-back", 0.7, 0.7, 0.0),
    ("back-stop", 0.7, 0.0, 0.0),
    ("turn-in-place-left", 0.0, 0.0, 0.5),
    ("turn-in-place-right", 0.0, 0.0, -0.5),
)
#: The direction of travel from the facing (rad, + = left) of the plan's kinds that do not walk forward.
_DIRECTIONS = {"step-left": np.pi / 2, "step-right": -np.pi / 2, "walk-back": np.pi, "back-stop": np.pi}

DEFAULT_NUM_CLIPS = len(_PLAN)
#: The data versions this package still makes, with how many of the plan's clips each holds: a
#: version only added clips at the plan's end, so an earlier one is a prefix of today's (a run
#: trained on one is evaluated on it again: mmrl.motion.sources).
VERSION_CLIPS = {2: 31, SYNTH_VERSION: DEFAULT_NUM_CLIPS}


def _check_version(version) -> None:
    if version not in VERSION_CLIPS:
        raise ValueError(f"synth: data version {version!r} is not one this mmrl makes ({sorted(VERSION_CLIPS)})")


def _clip_plan(num_clips: int, rng: np.random.Generator) -> List[Tuple[str, float, float, float]]:
    """The first `num_clips` plan entries with seeded jitter (speeds +-4%, turn rates +-8%);
    beyond the fixed plan, clips with random constant speed and turn rate."""
    plan = []
    for i in range(num_clips):
        if i < len(_PLAN):
            kind, v0, v1, w = _PLAN[i]
            jitter_v, jitter_w = rng.uniform(0.96, 1.04), rng.uniform(0.92, 1.08)
            plan.append((kind, round(v0 * jitter_v, 3), round(v1 * jitter_v, 3), round(w * jitter_w, 3)))
        else:
            v = round(float(rng.uniform(0.5, 4.0)), 3)
            w = round(float(rng.uniform(-1.2, 1.2)) * (1.0 if v < 2.5 else 0.6), 3)
            plan.append(("random", v, v, w))
    return plan


def write_dataset(out_dir, *, num_clips: Optional[int] = None, seconds_per_clip: float = 8.0,
                  fps: float = 30, seed: int = 0, version: int = SYNTH_VERSION) -> List[Path]:
    """Write a varied set of synthetic clips as BVH files plus ``manifest.json`` into `out_dir`.

    The set (in this order, repeating nothing): straight walk and run, left and right turns at walk
    and run, speed-ups and slow-downs, standing, walks at 0.5 to 1.8 m/s, runs at 2.4 to 4 m/s,
    sharp walking turns, turns in place, starting and stopping, gentle and sharp turns at other
    speeds, side steps to both sides, a backward walk, a backward walk that stops and slow turns in
    place (a fine correction of the facing at rest). Speeds and
    turn rates get a small seeded jitter. `num_clips` takes the first clips of that list
    (default: all 33, 4.4 minutes at 8 s each); more clips than that add random constant
    (speed, turn rate) clips.

    ``manifest.json``: {"generator": "mmrl.synth", "version", "seed", "fps", "clips": [{"file",
    "kind", "speed" (m/s, at the start), "speed_end" (m/s), "turn_rate" (rad/s, + = left),
    "direction" (rad, of travel from the facing, + = left),
    "ramp_seconds" ([start, end] of a linear speed ramp, or null), "frames", "fps",
    "contacts" (stance intervals per foot, [start, stop) frames)}]}.

    ``version``: the data version the manifest records; without ``num_clips``, that version's
    clips (:data:`VERSION_CLIPS`: 31 for version 2, all 33 today).

    Returns the BVH paths in clip order. Deterministic: the same arguments give the same bytes.
    """
    _check_version(version)
    if num_clips is None:
        num_clips = VERSION_CLIPS[version]
    if isinstance(num_clips, bool) or not isinstance(num_clips, (int, np.integer)) or num_clips < 1:
        raise ValueError(f"synth: num_clips must be a positive integer, got {num_clips!r}")
    _check_args(seconds_per_clip, fps)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    seeds = np.random.SeedSequence(seed)
    plan_rng = np.random.default_rng(seeds.spawn(1)[0])
    plan = _clip_plan(int(num_clips), plan_rng)
    clip_seeds = seeds.spawn(len(plan))
    paths, entries = [], []
    for i, ((kind, v0, v1, w), clip_seed) in enumerate(zip(plan, clip_seeds)):
        path = out_dir / f"synth_{i:03d}_{kind}.bvh"
        info = write_clip(path, speed=v0, speed_end=v1, turn_rate=w, direction=_DIRECTIONS.get(kind, 0.0),
                          seconds=seconds_per_clip, fps=fps, seed=int(clip_seed.generate_state(1)[0]))
        info["kind"] = kind
        entries.append(info)
        paths.append(path)
    manifest = {
        "generator": "mmrl.synth",
        "version": version,
        "seed": seed,
        "fps": fps,
        "units": {"speed": "m/s", "turn_rate": "rad/s, positive = left (counter-clockwise from above)"},
        "clips": entries,
    }
    atomic_write_text(out_dir / "manifest.json", json.dumps(manifest, indent=1) + "\n")
    return paths


def default_dataset_dir(version: int = SYNTH_VERSION) -> Path:
    """The default synthetic dataset, generated once on first use and cached; ``version``: an
    earlier one of :data:`VERSION_CLIPS` (its first clips).

    Location: ``<cache>/synth-v<version>`` where <cache> is ``$MMRL_CACHE`` if set, else
    ``$XDG_CACHE_HOME/mmrl``, else ``~/.cache/mmrl``. It holds ``write_dataset(dir)`` with the
    default arguments (33 clips, 4.4 minutes at 30 fps). Generation writes into a temporary
    sibling directory and renames it into place, so a crash never leaves a half-written dataset
    and concurrent first uses are safe (the loser of the race discards its copy).
    """
    from .data import cache_root

    _check_version(version)
    root = cache_root()
    final = root / f"synth-v{version}"
    if (final / "manifest.json").is_file():
        return final
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=root))
    try:
        write_dataset(tmp, version=version)
        try:
            os.rename(tmp, final)
        except OSError:
            if not (final / "manifest.json").is_file():  # not a lost race: a real failure
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def _main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m mmrl.motion.synth OUT_DIR [--num-clips N] [--seconds S] [--fps F] [--seed K]``."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m mmrl.motion.synth", description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--num-clips", type=int, default=None)
    parser.add_argument("--seconds", type=float, default=8.0)
    parser.add_argument("--fps", type=float, default=30)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    paths = write_dataset(args.out_dir, num_clips=args.num_clips, seconds_per_clip=args.seconds,
                          fps=args.fps, seed=args.seed)
    print(f"wrote {len(paths)} clips to {args.out_dir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
