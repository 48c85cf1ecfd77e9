"""Procedural biped locomotion written as BVH files: the test data and the default database.

A small generator of walking, running, turning, starting, stopping and standing clips at speeds
from 0 to 4 m/s, in pure numpy and deterministic from a seed. Nothing is downloaded, so the unit
tests need no data and a user without motion capture still gets a working motion-matching
database (``default_dataset_dir()``).

How a clip is made
------------------
1. Commands. A clip is commanded by a speed v(t) (m/s) and a turn rate w(t) (rad/s, positive =
   left = counter-clockwise seen from above). Both are integrated (trapezoid rule) into a root
   path on the ground: yaw(t) and p(t), with forward = (sin yaw, 0, cos yaw) and left = (cos yaw,
   0, -sin yaw). The hips follow p(t) plus a small lateral sway, so the hips' ground speed is the
   commanded speed.
2. Gait. A phase phi(t) advances at the stride frequency f(v) (1/s); the left foot is in stance
   while frac(phi) < duty(v), the right foot while frac(phi - 1/2) < duty(v). Walking (duty ~0.6,
   double support) blends into running (duty ~0.3, flight phases) between 2.0 and 2.5 m/s.
3. Footholds. Each stance interval gets one foothold, placed at the root pose of the interval's
   middle frame (half a step width to the side, toes slightly out). During stance the foot is
   flat and does not move at all: ankle and toe have exactly zero world velocity. Between
   footholds the foot swings on an arc whose horizontal progress and height both start and end
   with zero velocity.
4. Pelvis height. The hips aim for a nominal height (about 0.98 m walking, 0.95 m running) and are
   lowered where a foot would otherwise be out of the leg's reach (a smooth upper envelope of the
   reach limit), which also gives the walking bob at double support.
5. Legs. An analytic two-bone IK places hip, knee and ankle exactly (bone lengths are the
   skeleton's, by construction); the knee bends toward the foot's forward direction.
6. Upper body. The pelvis yaws and rolls a little with the gait and leans into turns; the chest
   counter-rotates; the head stays level and looks along the path; the arms swing in counter-phase
   with the legs, more and with more elbow bend when running.

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
- ``write_clip(path, *, speed, turn_rate=0.0, speed_end=None, seconds=8.0, fps=30, seed=0)``
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
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

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
SYNTH_VERSION = 1

# ---------------------------------------------------------------------------------------------
# Skeleton (centimetres; offsets in the parent's frame; rest pose: upright, X left, Y up, Z fwd)
# ---------------------------------------------------------------------------------------------
_THIGH_CM = 44.0
_SHIN_CM = 43.0
_HIP_JOINT_CM = (9.0, -5.0, 0.0)  # UpperLeg_L relative to Hips; _R mirrors x
_TOE_CM = (0.0, -6.0, 13.0)  # Toes relative to the ankle (Foot)
_ANKLE_HEIGHT_M = 0.08  # ankle above the floor when the foot is flat: toes then at 2 cm

# (name, parent name, offset cm, end-site offset cm or None)
_SKELETON: Tuple[Tuple[str, Optional[str], Tuple[float, float, float], Optional[Tuple[float, float, float]]], ...] = (
    ("Hips", None, (0.0, 0.0, 0.0), None),
    ("Spine", "Hips", (0.0, 10.0, -1.0), None),
    ("Chest", "Spine", (0.0, 14.0, 0.0), None),
    ("Neck", "Chest", (0.0, 24.0, 1.0), None),
    ("Head", "Neck", (0.0, 9.0, 1.0), (0.0, 18.0, 1.0)),
    ("Shoulder_L", "Chest", (4.0, 20.0, 0.0), None),
    ("UpperArm_L", "Shoulder_L", (13.0, 0.0, 0.0), None),
    ("LowerArm_L", "UpperArm_L", (0.0, -28.0, 0.0), None),
    ("Hand_L", "LowerArm_L", (0.0, -25.0, 0.0), (0.0, -17.0, 0.0)),
    ("Shoulder_R", "Chest", (-4.0, 20.0, 0.0), None),
    ("UpperArm_R", "Shoulder_R", (-13.0, 0.0, 0.0), None),
    ("LowerArm_R", "UpperArm_R", (0.0, -28.0, 0.0), None),
    ("Hand_R", "LowerArm_R", (0.0, -25.0, 0.0), (0.0, -17.0, 0.0)),
    ("UpperLeg_L", "Hips", _HIP_JOINT_CM, None),
    ("LowerLeg_L", "UpperLeg_L", (0.0, -_THIGH_CM, 0.0), None),
    ("Foot_L", "LowerLeg_L", (0.0, -_SHIN_CM, 0.0), None),
    ("Toes_L", "Foot_L", _TOE_CM, (0.0, 0.0, 6.0)),
    ("UpperLeg_R", "Hips", (-_HIP_JOINT_CM[0], _HIP_JOINT_CM[1], _HIP_JOINT_CM[2]), None),
    ("LowerLeg_R", "UpperLeg_R", (0.0, -_THIGH_CM, 0.0), None),
    ("Foot_R", "LowerLeg_R", (0.0, -_SHIN_CM, 0.0), None),
    ("Toes_R", "Foot_R", _TOE_CM, (0.0, 0.0, 6.0)),
)

JOINT_NAMES: Tuple[str, ...] = tuple(j[0] for j in _SKELETON)
JOINT_PARENTS: Tuple[int, ...] = tuple(-1 if j[1] is None else JOINT_NAMES.index(j[1]) for j in _SKELETON)
JOINT_OFFSETS_CM: Tuple[Tuple[float, float, float], ...] = tuple(j[2] for j in _SKELETON)
_J = {name: i for i, name in enumerate(JOINT_NAMES)}

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation")
_JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")  # local rotation = Rz * Ry * Rx

_GRAVITY = 9.81  # m/s^2, for the lean into turns


# ---------------------------------------------------------------------------------------------
# Small rotation helpers, vectorised over frames: angles (F,) in radians -> (F, 3, 3)
# ---------------------------------------------------------------------------------------------
def _rot(axis: int, angle: np.ndarray) -> np.ndarray:
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]  # right-handed rotation about X, Y or Z
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def _rx(a: np.ndarray) -> np.ndarray:
    return _rot(0, a)


def _ry(a: np.ndarray) -> np.ndarray:
    return _rot(1, a)


def _rz(a: np.ndarray) -> np.ndarray:
    return _rot(2, a)


def _forward(yaw: np.ndarray) -> np.ndarray:
    """Unit forward vectors (F, 3) for yaw angles (F,): (sin yaw, 0, cos yaw)."""
    return np.stack([np.sin(yaw), np.zeros_like(yaw), np.cos(yaw)], axis=-1)


def _left(yaw: np.ndarray) -> np.ndarray:
    """Unit left vectors (F, 3): the yawed local +X axis, (cos yaw, 0, -sin yaw)."""
    return np.stack([np.cos(yaw), np.zeros_like(yaw), -np.sin(yaw)], axis=-1)


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _euler_zyx_degrees(r: np.ndarray) -> np.ndarray:
    """Decompose rotation matrices (..., 3, 3) as Rz(a) Ry(b) Rx(c); returns (..., 3) = (a, b, c) in degrees."""
    b = np.arcsin(np.clip(-r[..., 2, 0], -1.0, 1.0))
    a = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    c = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    return np.degrees(np.stack([a, b, c], axis=-1))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _cumtrapz(y: np.ndarray, dt: float) -> np.ndarray:
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * dt, axis=0)
    return out


def _runs(mask: np.ndarray) -> List[Tuple[int, int]]:
    """Runs of True in a boolean array as (start, stop) pairs, stop exclusive."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def _upper_envelope(deficit: np.ndarray, radius: int) -> np.ndarray:
    """A smooth curve that is >= deficit everywhere: a running max over +-radius frames, then a
    binomial (Gaussian-like) average with the same support. Each output sample averages values
    that are each >= the input at that sample, so the bound holds exactly."""
    n = len(deficit)
    padded = np.pad(deficit, radius, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1)
    running_max = windows.max(axis=1)
    kernel = np.array([1.0])
    for _ in range(2 * radius):
        kernel = np.convolve(kernel, [0.5, 0.5])
    padded = np.pad(running_max, radius, mode="edge")
    return np.convolve(padded, kernel, mode="valid")[:n]


# ---------------------------------------------------------------------------------------------
# Per-clip style: small seeded variations so that clips are not identical copies of each other
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Style:
    cadence_scale: float  # multiplies the stride frequency
    step_half_width: float  # m, foothold distance from the path centre when walking
    toe_out: float  # rad, feet turned outward
    walk_height: float  # m, nominal hips height when walking
    arm_swing_scale: float
    phase0: float  # gait phase at the first padded frame
    idle_phase: float


def _draw_style(rng: np.random.Generator) -> _Style:
    return _Style(
        cadence_scale=float(rng.uniform(0.96, 1.04)),
        step_half_width=float(rng.uniform(0.085, 0.11)),
        toe_out=float(np.radians(rng.uniform(3.0, 8.0))),
        walk_height=float(rng.uniform(0.975, 0.99)),
        arm_swing_scale=float(rng.uniform(0.85, 1.15)),
        phase0=float(rng.uniform(0.0, 1.0)),
        idle_phase=float(rng.uniform(0.0, 2.0 * np.pi)),
    )


# ---------------------------------------------------------------------------------------------
# Animation
# ---------------------------------------------------------------------------------------------
@dataclass
class _Clip:
    """An animated clip: root translation (F, 3) cm, root yaw/pitch/roll (F, 3) degrees for the
    Yrotation Xrotation Zrotation channels, local rotations (F, J, 3, 3), and stance intervals."""

    root_position_cm: np.ndarray
    root_yxz_degrees: np.ndarray
    local_rotations: np.ndarray
    contacts: Dict[str, List[Tuple[int, int]]]


def _two_bone_ik(hip: np.ndarray, target: np.ndarray, pole: np.ndarray, upper: float, lower: float):
    """Analytic two-bone IK, vectorised over frames; lengths in metres.

    Returns the world rotations (F, 3, 3) of the upper and lower bone, whose rest direction is
    local -Y and whose hinge axis is local +X; the knee bends toward `pole` (F, 3). The
    hip-target distance is clamped into the reachable range, so the caller must plan targets
    within reach (the planner keeps a margin) for the ankle to land exactly on the target.
    """
    d = target - hip
    dist = np.linalg.norm(d, axis=-1)
    dist_c = np.clip(dist, abs(upper - lower) + 1e-4, upper + lower - 1e-5)
    d_hat = d / dist[:, None]
    hinge = _normalize(np.cross(pole, d_hat))  # knee axis, roughly the character's left
    bend_dir = np.cross(d_hat, hinge)  # in the leg plane, perpendicular to d, toward the pole
    cos_a = (upper**2 + dist_c**2 - lower**2) / (2.0 * upper * dist_c)
    sin_a = np.sqrt(np.clip(1.0 - cos_a**2, 0.0, 1.0))
    knee = hip + upper * (cos_a[:, None] * d_hat + sin_a[:, None] * bend_dir)
    ankle = hip + dist_c[:, None] * d_hat  # == target whenever it is within reach

    def frame(y_axis: np.ndarray) -> np.ndarray:
        z_axis = np.cross(hinge, y_axis)
        return np.stack([hinge, y_axis, z_axis], axis=-1)  # columns: local X, Y, Z in world

    return frame(_normalize(hip - knee)), frame(_normalize(knee - ankle))


def _foot_track(stance: np.ndarray, side: float, path_xz: np.ndarray, yaw: np.ndarray,
                run_weight: np.ndarray, style: _Style):
    """Ankle targets (F, 3) m, foot yaw (F,) and foot pitch (F,) rad (positive = toes down) for
    one foot (side +1 = left, -1 = right) from its stance mask."""
    n = len(stance)
    runs = _runs(stance)
    if not runs:
        raise RuntimeError("synth: the gait produced no stance phase; clip too short")
    idx = np.arange(n, dtype=np.float64)
    ankle = np.zeros((n, 3))
    ankle[:, 1] = _ANKLE_HEIGHT_M
    foot_yaw = np.zeros(n)
    pitch = np.zeros(n)
    holds, hold_yaws = [], []
    for start, stop in runs:
        mid = 0.5 * (start + stop - 1)
        yaw_mid = np.interp(mid, idx, yaw)
        centre = np.array([np.interp(mid, idx, path_xz[:, 0]), np.interp(mid, idx, path_xz[:, 1])])
        w_run = np.interp(mid, idx, run_weight)
        half_width = (1.0 - w_run) * style.step_half_width + w_run * 0.06  # runners step narrower
        hold = centre + side * half_width * np.array([np.cos(yaw_mid), -np.sin(yaw_mid)])
        holds.append(hold)
        hold_yaws.append(yaw_mid + side * style.toe_out)
        ankle[start:stop, 0], ankle[start:stop, 2] = hold
        foot_yaw[start:stop] = hold_yaws[-1]
    for k in range(len(runs) - 1):
        last = runs[k][1] - 1  # last stance frame (foot still flat and still)
        first = runs[k + 1][0]  # first frame of the next stance
        frames = np.arange(last + 1, first)
        if len(frames) == 0:
            continue
        s = (frames - last) / float(first - last)
        a, b = holds[k], holds[k + 1]
        ya, yb = hold_yaws[k], hold_yaws[k + 1]
        progress = s - np.sin(2.0 * np.pi * s) / (2.0 * np.pi)  # 0 -> 1 with zero end velocities
        w_run = run_weight[frames].mean()
        # 0 -> 1 -> 0 with zero end velocities; running lifts early (heel kick behind the body)
        lift = np.sin(np.pi * s ** (1.0 - 0.3 * w_run)) ** 2
        step = np.linalg.norm(b - a) + 0.15 * abs(yb - ya)
        size = min(1.0, step / 0.25)  # stepping in place (standing) lifts nothing
        clearance = size * ((1.0 - w_run) * 0.09 + w_run * 0.28)
        ankle[frames, 0] = a[0] + (b[0] - a[0]) * progress
        ankle[frames, 2] = a[1] + (b[1] - a[1]) * progress
        ankle[frames, 1] = _ANKLE_HEIGHT_M + clearance * lift
        foot_yaw[frames] = ya + (yb - ya) * progress
        # toes down after push-off, toes up before landing; zero at both ends, smaller than the lift
        pitch[frames] = size * np.radians(20.0) * np.sin(2.0 * np.pi * s) * lift
    first_start, last_stop = runs[0][0], runs[-1][1]
    ankle[:first_start, 0], ankle[:first_start, 2] = holds[0]
    foot_yaw[:first_start] = hold_yaws[0]
    ankle[last_stop:, 0], ankle[last_stop:, 2] = holds[-1]
    foot_yaw[last_stop:] = hold_yaws[-1]
    return ankle, foot_yaw, pitch


def _animate(speed: np.ndarray, turn_rate: np.ndarray, fps: float, pad: int, yaw0: float,
             origin_xz: np.ndarray, style: _Style) -> _Clip:
    """Animate commanded speed (F,) m/s and turn rate (F,) rad/s sampled on padded frames; the
    clip is frames [pad, F - pad)."""
    n = len(speed)
    dt = 1.0 / fps
    t = (np.arange(n) - pad) * dt

    # 1. root path on the ground
    yaw = _cumtrapz(turn_rate, dt)
    yaw += yaw0 - yaw[pad]
    vel = speed[:, None] * _forward(yaw)[:, [0, 2]]
    path_xz = _cumtrapz(vel, dt)
    path_xz += origin_xz - path_xz[pad]

    # 2. gait timing
    gait_speed = np.maximum(speed, 0.5 * np.abs(turn_rate))  # turning in place still steps
    motion = np.clip(gait_speed / 0.8, 0.0, 1.0)  # 0 standing .. 1 locomoting (scales secondary motion)
    w_run = _smoothstep((speed - 2.0) / 0.5)
    stride_freq = style.cadence_scale * ((1.0 - w_run) * (0.75 + 0.25 * gait_speed)
                                         + w_run * (1.40 + 0.15 * (speed - 2.5)))  # strides/s
    duty = (1.0 - w_run) * (0.62 - 0.04 * gait_speed) + w_run * (0.34 - 0.04 * (speed - 2.5))
    phase = style.phase0 + _cumtrapz(stride_freq, dt)
    stance_l = np.mod(phase, 1.0) < duty
    stance_r = np.mod(phase - 0.5, 1.0) < duty
    # gait-synchronous oscillator: +1 at left mid-stance, -1 at right mid-stance
    mid_stance_wave = np.cos(2.0 * np.pi * (phase - 0.5 * duty))

    ankle_l, yaw_l, pitch_l = _foot_track(stance_l, +1.0, path_xz, yaw, w_run, style)
    ankle_r, yaw_r, pitch_r = _foot_track(stance_r, -1.0, path_xz, yaw, w_run, style)

    # 3. pelvis: yaw with the stepping leg, sway over the stance foot, lean forward and into turns
    pelvis_twist = -motion * np.radians((1.0 - w_run) * 5.0 + w_run * 3.0) * np.cos(2.0 * np.pi * phase)
    pelvis_yaw = yaw + pelvis_twist
    pelvis_tilt = np.radians(2.0 + 1.5 * speed)
    turn_lean = -0.6 * np.arctan(speed * turn_rate / _GRAVITY)
    pelvis_roll = turn_lean + motion * np.radians(2.0) * mid_stance_wave
    idle = (1.0 - motion) * np.sin(2.0 * np.pi * 0.2 * t + style.idle_phase)  # slow weight shift
    sway = motion * ((1.0 - w_run) * 0.025 + w_run * 0.01) * mid_stance_wave + 0.012 * idle
    hips = np.zeros((n, 3))
    hips[:, [0, 2]] = path_xz + sway[:, None] * _left(yaw)[:, [0, 2]]
    hips_rot = _ry(pelvis_yaw) @ _rx(pelvis_tilt) @ _rz(pelvis_roll)

    # 4. pelvis height: nominal + bob, lowered wherever a foot would be out of reach
    bob_wave = np.cos(4.0 * np.pi * (phase - 0.5 * duty))  # +1 at each mid-stance
    height = ((1.0 - w_run) * (style.walk_height + 0.01 * motion * bob_wave)
              + w_run * (0.93 - 0.02 * bob_wave))
    upper, lower = _THIGH_CM / 100.0, _SHIN_CM / 100.0
    reach = upper + lower - 0.006  # keep the knee a little bent (about 12 degrees)
    max_height = np.full(n, np.inf)
    hip_offsets = {}
    for side, ankle in (("L", ankle_l), ("R", ankle_r)):
        local = np.array(JOINT_OFFSETS_CM[_J["UpperLeg_" + side]]) / 100.0
        offset = hips_rot @ local  # hip joint relative to the hips, world axes
        hip_offsets[side] = offset
        horizontal = np.linalg.norm(hips[:, [0, 2]] + offset[:, [0, 2]] - ankle[:, [0, 2]], axis=-1)
        # the outer padding (beyond the first and last whole step) is cut away: clamp it there
        if np.any(horizontal[pad // 2:n - pad // 2] >= reach):
            raise RuntimeError("synth: a planned foothold is out of the leg's reach; speed too high")
        horizontal = np.minimum(horizontal, reach - 1e-3)
        max_height = np.minimum(max_height, ankle[:, 1] - offset[:, 1] + np.sqrt(reach**2 - horizontal**2))
    radius = max(1, int(round(0.07 * fps)))  # short, so that the dips stay where the reach binds
    height -= _upper_envelope(np.maximum(0.0, height - max_height), radius)
    hips[:, 1] = height

    # 5. legs by two-bone IK; feet flat in stance, pitched during swing
    world = np.zeros((n, len(JOINT_NAMES), 3, 3))
    world[:, :] = np.eye(3)
    world[:, _J["Hips"]] = hips_rot
    for side, ankle, foot_yaw, pitch in (("L", ankle_l, yaw_l, pitch_l), ("R", ankle_r, yaw_r, pitch_r)):
        hip_joint = hips + hip_offsets[side]
        pole = _normalize(_forward(foot_yaw) + _forward(pelvis_yaw))
        thigh, shin = _two_bone_ik(hip_joint, ankle, pole, upper, lower)
        world[:, _J["UpperLeg_" + side]] = thigh
        world[:, _J["LowerLeg_" + side]] = shin
        world[:, _J["Foot_" + side]] = _ry(foot_yaw) @ _rx(pitch)
        world[:, _J["Toes_" + side]] = world[:, _J["Foot_" + side]]

    local = np.zeros_like(world)
    local[:, :] = np.eye(3)
    for name in ("UpperLeg", "LowerLeg", "Foot", "Toes"):
        for side in ("L", "R"):
            j = _J[f"{name}_{side}"]
            parent = JOINT_PARENTS[j]
            local[:, j] = np.swapaxes(world[:, parent], -1, -2) @ world[:, j]

    # 6. upper body, directly as local rotations
    spine_lean = np.radians(1.0 + 2.5 * speed)
    local[:, _J["Spine"]] = _ry(-0.7 * pelvis_twist) @ _rx(spine_lean)
    local[:, _J["Chest"]] = _ry(-0.7 * pelvis_twist) @ _rz(-0.5 * (pelvis_roll - turn_lean))
    head_pitch = -0.5 * (pelvis_tilt + spine_lean)
    head_roll = -0.5 * pelvis_roll
    local[:, _J["Neck"]] = _ry(0.2 * pelvis_twist) @ _rx(head_pitch) @ _rz(head_roll)
    local[:, _J["Head"]] = _ry(0.2 * pelvis_twist) @ _rx(head_pitch) @ _rz(head_roll)
    arm_amplitude = style.arm_swing_scale * motion * np.radians(np.minimum(12.0 + 8.0 * speed, 40.0))
    arm_forward = np.radians(10.0) * w_run
    elbow = np.radians((1.0 - w_run) * (12.0 + 6.0 * speed) + w_run * 85.0)
    for side, sign in (("L", 1.0), ("R", -1.0)):
        # left arm swings back when the left foot lands (phase 0), counter to the legs
        swing = sign * arm_amplitude * np.cos(2.0 * np.pi * phase) - arm_forward
        local[:, _J["UpperArm_" + side]] = _rz(sign * np.radians(8.0) * np.ones(n)) @ _rx(swing)
        local[:, _J["LowerArm_" + side]] = _rx(-(elbow + 0.3 * arm_amplitude * np.cos(2.0 * np.pi * phase) * sign))

    # 7. crop the padding
    keep = slice(pad, n - pad)
    root_yxz = np.degrees(np.stack([pelvis_yaw, pelvis_tilt * np.ones(n), pelvis_roll], axis=-1))
    contacts = {}
    for side, stance in (("left", stance_l[keep]), ("right", stance_r[keep])):
        contacts[side] = [(int(a), int(b)) for a, b in _runs(stance)]
    return _Clip(
        root_position_cm=hips[keep] * 100.0,
        root_yxz_degrees=root_yxz[keep],
        local_rotations=local[keep],
        contacts=contacts,
    )


# ---------------------------------------------------------------------------------------------
# BVH writing
# ---------------------------------------------------------------------------------------------
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


def _write_text_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="ascii", newline="\n") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------
_RAMP = (0.3, 0.7)  # speed changes ramp linearly between these fractions of the clip


def _check_args(seconds: float, fps: float) -> None:
    if not (np.isfinite(seconds) and seconds >= 1.0):
        raise ValueError(f"synth: seconds per clip must be >= 1, got {seconds!r}")
    if not (np.isfinite(fps) and 1.0 <= fps <= 1000.0):
        raise ValueError(f"synth: fps must be in [1, 1000], got {fps!r}")


def _check_command(speed: float, speed_end: float, turn_rate: float) -> None:
    for name, value in (("speed", speed), ("speed_end", speed_end)):
        if not (np.isfinite(value) and 0.0 <= value <= 4.5):
            raise ValueError(f"synth: {name} must be in [0, 4.5] m/s, got {value!r}")
    if not (np.isfinite(turn_rate) and abs(turn_rate) <= 3.0):
        raise ValueError(f"synth: turn_rate must be in [-3, 3] rad/s, got {turn_rate!r}")


def _synthesize(speed: float, speed_end: float, turn_rate: float, seconds: float, fps: float,
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
    return _animate(v, w, float(fps), pad, yaw0, origin, style), num_frames


def write_clip(path, *, speed: float, turn_rate: float = 0.0, speed_end: Optional[float] = None,
               seconds: float = 8.0, fps: float = 30, seed: int = 0) -> dict:
    """Write one synthetic clip to the BVH file `path` and return its description.

    speed: commanded ground speed in m/s (0 = standing or turning in place; up to 4.5).
    turn_rate: commanded yaw rate in rad/s, positive = turning left (counter-clockwise from above).
    speed_end: if given, the speed ramps linearly from `speed` to `speed_end` between 30% and 70%
        of the clip (a start, stop or speed change); otherwise the speed is constant.
    seconds, fps: clip length and frame rate. seed: gait style, start position and start heading.

    Returns a dict with the commanded values, the frame count, and the stance intervals of each
    foot (``contacts``: {"left": [[start, stop), ...], "right": ...} in frames), as stored in a
    dataset manifest. The same arguments always give the same bytes.
    """
    speed_end = float(speed if speed_end is None else speed_end)
    _check_args(seconds, fps)
    _check_command(float(speed), speed_end, float(turn_rate))
    rng = np.random.default_rng(seed)
    clip, num_frames = _synthesize(float(speed), speed_end, float(turn_rate), float(seconds), float(fps), rng)
    path = Path(path)
    _write_text_atomic(path, _bvh_text(clip, fps))
    return {
        "file": path.name,
        "speed": float(speed),
        "speed_end": speed_end,
        "turn_rate": float(turn_rate),
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
)

DEFAULT_NUM_CLIPS = len(_PLAN)


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
                  fps: float = 30, seed: int = 0) -> List[Path]:
    """Write a varied set of synthetic clips as BVH files plus ``manifest.json`` into `out_dir`.

    The set (in this order, repeating nothing): straight walk and run, left and right turns at walk
    and run, speed-ups and slow-downs, standing, walks at 0.5 to 1.8 m/s, runs at 2.4 to 4 m/s,
    sharp walking turns, turns in place, starting and stopping, gentle and sharp turns at other
    speeds. Speeds and turn rates get a small seeded jitter. `num_clips` takes the first clips of
    that list (default: all 27, 3.6 minutes at 8 s each); more clips than that add random constant
    (speed, turn rate) clips.

    ``manifest.json``: {"generator": "mmrl.synth", "version", "seed", "fps", "clips": [{"file",
    "kind", "speed" (m/s, at the start), "speed_end" (m/s), "turn_rate" (rad/s, + = left),
    "ramp_seconds" ([start, end] of a linear speed ramp, or null), "frames", "fps",
    "contacts" (stance intervals per foot, [start, stop) frames)}]}.

    Returns the BVH paths in clip order. Deterministic: the same arguments give the same bytes.
    """
    if num_clips is None:
        num_clips = DEFAULT_NUM_CLIPS
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
        info = write_clip(path, speed=v0, speed_end=v1, turn_rate=w, seconds=seconds_per_clip,
                          fps=fps, seed=int(clip_seed.generate_state(1)[0]))
        info["kind"] = kind
        entries.append(info)
        paths.append(path)
    manifest = {
        "generator": "mmrl.synth",
        "version": SYNTH_VERSION,
        "seed": seed,
        "fps": fps,
        "units": {"speed": "m/s", "turn_rate": "rad/s, positive = left (counter-clockwise from above)"},
        "clips": entries,
    }
    _write_text_atomic(out_dir / "manifest.json", json.dumps(manifest, indent=1) + "\n")
    return paths


def default_dataset_dir() -> Path:
    """The default synthetic dataset, generated once on first use and cached.

    Location: ``<cache>/synth-v<SYNTH_VERSION>`` where <cache> is ``$MMRL_CACHE`` if set, else
    ``$XDG_CACHE_HOME/mmrl``, else ``~/.cache/mmrl``. It holds ``write_dataset(dir)`` with the
    default arguments (27 clips, 3.6 minutes at 30 fps). Generation writes into a temporary
    sibling directory and renames it into place, so a crash never leaves a half-written dataset
    and concurrent first uses are safe (the loser of the race discards its copy).
    """
    from .data import cache_root

    root = cache_root()
    final = root / f"synth-v{SYNTH_VERSION}"
    if (final / "manifest.json").is_file():
        return final
    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=root))
    try:
        write_dataset(tmp)
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
    """``python -m mmrl.synth OUT_DIR [--num-clips N] [--seconds S] [--fps F] [--seed K]``."""
    import argparse

    parser = argparse.ArgumentParser(prog="python -m mmrl.synth", description=__doc__.splitlines()[0])
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
