"""The procedural animation behind :mod:`mmrl.motion.synth`: commands to a root path, gait timing,
footholds, pelvis, two-bone IK legs and the upper body, as joint rotations per frame.

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

Skeleton (the rest pose, all rotations zero, stands upright with the arms hanging down):
centimetres, Y up, the character faces +Z at yaw 0 and +X is its left; offsets in the parent's
frame. World rotations below are (F, 3, 3) matrices whose columns are the joint's local X, Y, Z
axes in world coordinates (metres, Y up). :mod:`mmrl.motion.synth` writes the result as BVH.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

# ---------------------------------------------------------------------------------------------
# Skeleton (centimetres; offsets in the parent's frame; rest pose: upright, X left, Y up, Z fwd)
# ---------------------------------------------------------------------------------------------
_THIGH_CM = 44.0
_SHIN_CM = 43.0
_HIP_JOINT_CM = (9.0, -5.0, 0.0)  # UpperLeg_L relative to Hips; _R mirrors x
_TOE_CM = (0.0, -6.0, 13.0)  # Toes relative to the ankle (Foot)
_ANKLE_HEIGHT_M = 0.08  # ankle above the floor when the foot is flat: toes then at 2 cm
_THIGH_M, _SHIN_M = _THIGH_CM / 100.0, _SHIN_CM / 100.0  # the IK's bone lengths

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



# ---------------------------------------------------------------------------------------------
# Animation, step by step (all arrays over the padded frames; metres, radians, world axes)
# ---------------------------------------------------------------------------------------------
@dataclass
class _Gait:
    """Gait timing per frame (step 2)."""

    motion: np.ndarray  # 0 standing .. 1 locomoting (scales secondary motion)
    w_run: np.ndarray  # 0 walking .. 1 running
    phase: np.ndarray  # gait phase in strides; the left foot lands at whole numbers
    duty: np.ndarray  # stance fraction of a stride
    stance_l: np.ndarray  # bool, left foot on the ground
    stance_r: np.ndarray
    mid_stance_wave: np.ndarray  # +1 at left mid-stance, -1 at right mid-stance


@dataclass
class _Pelvis:
    """The hips (the BVH root) per frame (steps 3 and 4)."""

    twist: np.ndarray  # rad, yaw relative to the path, with the stepping leg
    yaw: np.ndarray  # rad, path yaw + twist
    tilt: np.ndarray  # rad, forward lean
    turn_lean: np.ndarray  # rad, roll into turns
    roll: np.ndarray  # rad, turn lean + sway with the stance foot
    position: np.ndarray  # (F, 3) m; the height is filled by _lower_pelvis
    rotation: np.ndarray  # (F, 3, 3) world


def _root_path(speed: np.ndarray, turn_rate: np.ndarray, dt: float, pad: int, yaw0: float,
               origin_xz: np.ndarray, direction: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """Step 1: the commands integrated into yaw (F,) rad and ground positions (F, 2) m (x, z),
    placed so that the first kept frame (index `pad`) is at `origin_xz` facing `yaw0`; the body
    travels at `direction` rad from its facing (+pi/2 steps to its left, pi backwards)."""
    yaw = _cumtrapz(turn_rate, dt)
    yaw += yaw0 - yaw[pad]
    vel = speed[:, None] * _forward(yaw + direction)[:, [0, 2]]
    path_xz = _cumtrapz(vel, dt)
    path_xz += origin_xz - path_xz[pad]
    return yaw, path_xz


def _gait_timing(speed: np.ndarray, turn_rate: np.ndarray, dt: float, style: _Style) -> _Gait:
    """Step 2: stride frequency and duty factor from the speed, walking blended into running."""
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
    return _Gait(motion, w_run, phase, duty, stance_l, stance_r, mid_stance_wave)


def _pelvis_motion(speed: np.ndarray, turn_rate: np.ndarray, t: np.ndarray, yaw: np.ndarray,
                   path_xz: np.ndarray, gait: _Gait, style: _Style) -> _Pelvis:
    """Step 3: pelvis yaw with the stepping leg, sway over the stance foot, lean forward and
    into turns; the height is left at zero for :func:`_lower_pelvis`."""
    motion, w_run = gait.motion, gait.w_run
    pelvis_twist = -motion * np.radians((1.0 - w_run) * 5.0 + w_run * 3.0) * np.cos(2.0 * np.pi * gait.phase)
    pelvis_yaw = yaw + pelvis_twist
    pelvis_tilt = np.radians(2.0 + 1.5 * speed)
    turn_lean = -0.6 * np.arctan(speed * turn_rate / _GRAVITY)
    pelvis_roll = turn_lean + motion * np.radians(2.0) * gait.mid_stance_wave
    idle = (1.0 - motion) * np.sin(2.0 * np.pi * 0.2 * t + style.idle_phase)  # slow weight shift
    sway = motion * ((1.0 - w_run) * 0.025 + w_run * 0.01) * gait.mid_stance_wave + 0.012 * idle
    hips = np.zeros((len(t), 3))
    hips[:, [0, 2]] = path_xz + sway[:, None] * _left(yaw)[:, [0, 2]]
    hips_rot = _ry(pelvis_yaw) @ _rx(pelvis_tilt) @ _rz(pelvis_roll)
    return _Pelvis(pelvis_twist, pelvis_yaw, pelvis_tilt, turn_lean, pelvis_roll, hips, hips_rot)


def _lower_pelvis(pelvis: _Pelvis, ankles: Dict[str, np.ndarray], gait: _Gait, style: _Style, fps: float,
                  pad: int) -> Dict[str, np.ndarray]:
    """Step 4: set the hips height (nominal + bob, lowered wherever a foot would be out of
    reach) in ``pelvis.position``; returns each hip joint's offset from the hips (F, 3), world."""
    n = len(pelvis.position)
    hips = pelvis.position
    w_run, motion = gait.w_run, gait.motion
    bob_wave = np.cos(4.0 * np.pi * (gait.phase - 0.5 * gait.duty))  # +1 at each mid-stance
    height = ((1.0 - w_run) * (style.walk_height + 0.01 * motion * bob_wave)
              + w_run * (0.93 - 0.02 * bob_wave))
    reach = _THIGH_M + _SHIN_M - 0.006  # keep the knee a little bent (about 12 degrees)
    max_height = np.full(n, np.inf)
    hip_offsets = {}
    for side in ("L", "R"):
        ankle = ankles[side]
        local = np.array(JOINT_OFFSETS_CM[_J["UpperLeg_" + side]]) / 100.0
        offset = pelvis.rotation @ local  # hip joint relative to the hips, world axes
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
    return hip_offsets


def _leg_rotations(pelvis: _Pelvis, hip_offsets: Dict[str, np.ndarray], feet: dict) -> np.ndarray:
    """Step 5: local rotations (F, J, 3, 3) with the legs by two-bone IK (feet flat in stance,
    pitched during swing) and every other joint at identity. `feet`: side -> (ankle (F, 3) m,
    foot yaw (F,) rad, foot pitch (F,) rad)."""
    n = len(pelvis.position)
    world = np.zeros((n, len(JOINT_NAMES), 3, 3))
    world[:, :] = np.eye(3)
    world[:, _J["Hips"]] = pelvis.rotation
    for side in ("L", "R"):
        ankle, foot_yaw, pitch = feet[side]
        hip_joint = pelvis.position + hip_offsets[side]
        pole = _normalize(_forward(foot_yaw) + _forward(pelvis.yaw))
        thigh, shin = _two_bone_ik(hip_joint, ankle, pole, _THIGH_M, _SHIN_M)
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
    return local


def _upper_body_rotations(local: np.ndarray, speed: np.ndarray, pelvis: _Pelvis, gait: _Gait,
                          style: _Style) -> None:
    """Step 6: spine, chest, neck, head and arms, written directly as local rotations into `local`."""
    n = len(speed)
    w_run, phase = gait.w_run, gait.phase
    spine_lean = np.radians(1.0 + 2.5 * speed)
    local[:, _J["Spine"]] = _ry(-0.7 * pelvis.twist) @ _rx(spine_lean)
    local[:, _J["Chest"]] = _ry(-0.7 * pelvis.twist) @ _rz(-0.5 * (pelvis.roll - pelvis.turn_lean))
    head_pitch = -0.5 * (pelvis.tilt + spine_lean)
    head_roll = -0.5 * pelvis.roll
    local[:, _J["Neck"]] = _ry(0.2 * pelvis.twist) @ _rx(head_pitch) @ _rz(head_roll)
    local[:, _J["Head"]] = _ry(0.2 * pelvis.twist) @ _rx(head_pitch) @ _rz(head_roll)
    arm_amplitude = style.arm_swing_scale * gait.motion * np.radians(np.minimum(12.0 + 8.0 * speed, 40.0))
    arm_forward = np.radians(10.0) * w_run
    elbow = np.radians((1.0 - w_run) * (12.0 + 6.0 * speed) + w_run * 85.0)
    for side, sign in (("L", 1.0), ("R", -1.0)):
        # left arm swings back when the left foot lands (phase 0), counter to the legs
        swing = sign * arm_amplitude * np.cos(2.0 * np.pi * phase) - arm_forward
        local[:, _J["UpperArm_" + side]] = _rz(sign * np.radians(8.0) * np.ones(n)) @ _rx(swing)
        local[:, _J["LowerArm_" + side]] = _rx(-(elbow + 0.3 * arm_amplitude * np.cos(2.0 * np.pi * phase) * sign))


def _crop(pelvis: _Pelvis, local: np.ndarray, gait: _Gait, pad: int) -> _Clip:
    """Step 7: drop the padding; root channels in BVH units (cm, degrees)."""
    n = len(local)
    keep = slice(pad, n - pad)
    root_yxz = np.degrees(np.stack([pelvis.yaw, pelvis.tilt * np.ones(n), pelvis.roll], axis=-1))
    contacts = {}
    for side, stance in (("left", gait.stance_l[keep]), ("right", gait.stance_r[keep])):
        contacts[side] = [(int(a), int(b)) for a, b in _runs(stance)]
    return _Clip(
        root_position_cm=pelvis.position[keep] * 100.0,
        root_yxz_degrees=root_yxz[keep],
        local_rotations=local[keep],
        contacts=contacts,
    )


def _animate(speed: np.ndarray, turn_rate: np.ndarray, fps: float, pad: int, yaw0: float,
             origin_xz: np.ndarray, style: _Style, direction: float = 0.0) -> _Clip:
    """Animate commanded speed (F,) m/s and turn rate (F,) rad/s sampled on padded frames, the
    body travelling at `direction` rad from its facing; the clip is frames [pad, F - pad)."""
    n = len(speed)
    dt = 1.0 / fps
    t = (np.arange(n) - pad) * dt
    yaw, path_xz = _root_path(speed, turn_rate, dt, pad, yaw0, origin_xz, direction)
    gait = _gait_timing(speed, turn_rate, dt, style)
    feet = {"L": _foot_track(gait.stance_l, +1.0, path_xz, yaw, gait.w_run, style),
            "R": _foot_track(gait.stance_r, -1.0, path_xz, yaw, gait.w_run, style)}
    pelvis = _pelvis_motion(speed, turn_rate, t, yaw, path_xz, gait, style)
    hip_offsets = _lower_pelvis(pelvis, {side: foot[0] for side, foot in feet.items()}, gait, style, fps, pad)
    local = _leg_rotations(pelvis, hip_offsets, feet)
    _upper_body_rotations(local, speed, pelvis, gait, style)
    return _crop(pelvis, local, gait, pad)
