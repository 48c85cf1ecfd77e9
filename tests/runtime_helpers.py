"""Shared by the runtime tests: drive the C++ runtime (mmrl_runtime, through mmrl._core) and
Python's full path (mmrl.rollout.FullPath, as ``mmrl play`` does) side by side."""
from __future__ import annotations

import numpy as np

from mmrl import _core
from mmrl.rollout import FullPath


def scripted_targets(n: int, seed: int, half: float = 6.0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-half, half, (n, 2))


def start_both(path, task, db, config, seed, compressed, start):
    """The Python full path and a runtime character of the controller file ``path`` on the same
    start (``start``: see drive_both), and the loaded controller."""
    fp = FullPath(task, db, config=config, seed=seed, record=False, continuous=True, compressed=compressed)
    if start is not None:
        fp.env.set_state(0, int(start[0]), 0.0, 0.0, 0.0)
        fp._start_episode()
    x, z, yaw = fp.character.root
    controller = _core.RuntimeController.load(str(path))
    ch = _core.RuntimeCharacter(controller, x, z, yaw, fp.character.frame if start is None else int(start[1]))
    return fp, ch, controller


def drive_both(path, task, db, config, python_act, decisions: int, seed: int = 0, success_radius: float = 0.5,
               request: str = "", compressed=None, start=None):
    """``decisions`` decisions of the runtime and of the Python full path from the same start,
    through the same scripted targets (the next one once the root is within success_radius at
    a decision). ``python_act(obs) -> action`` is the Python side's policy. ``compressed``: the
    Python side's CompressedModel; ``start``: (the Python side's start frame, the runtime's)
    when they differ (a compressed file keeps only its start windows).

    Returns per decision the matches of both, and the largest root and pose differences per frame."""
    fp, ch, controller = start_both(path, task, db, config, seed, compressed, start)
    if request:  # the same request on both sides (tags.hpp)
        fp.env.set_request(0, request)
        fp.obs = fp.env.observe(0)
        ch.set_request(request)
    targets = scripted_targets(decisions + 1, seed)
    t = 0
    fp.set_target(*targets[0])
    ch.set_target(*targets[0])
    out = {"py_matches": [], "rt_matches": [], "frame_mismatches": 0, "root_error": 0.0, "pose_error": 0.0,
           "obs_error": 0.0, "targets_reached": 0}
    for _ in range(decisions):
        root = fp.character.root
        if np.hypot(root[0] - targets[t][0], root[1] - targets[t][1]) < success_radius:
            t += 1
            fp.set_target(*targets[t])
            ch.set_target(*targets[t])
        out["obs_error"] = max(out["obs_error"], float(np.max(np.abs(ch.observe() - fp.obs))))
        step = fp.step(np.asarray(python_act(fp.obs), np.float32).reshape(-1))
        if step["done"]:
            fp.continue_from_character(fp.target)
        res = step["res"]
        for k in range(res.frames.size):
            ch.advance_frame()
            out["frame_mismatches"] += int(ch.frame != res.frames[k])
            out["root_error"] = max(out["root_error"], float(np.max(np.abs(np.array(ch.root) - res.roots[k]))))
            out["pose_error"] = max(out["pose_error"], float(np.max(np.abs(ch.global_positions() - res.positions[k]))))
        out["py_matches"].append(res.match)
        out["rt_matches"].append(ch.last_decision()["match"])
    out["targets_reached"] = t
    out["py_matches"], out["rt_matches"] = np.array(out["py_matches"]), np.array(out["rt_matches"])
    return out


def drive_stick(path, task, db, config, phases, seed: int = 0, request: str = "", compressed=None, start=None,
                runtime_actions: bool = False, stop_at_done: bool = False):
    """The runtime driven by a stick (RuntimeCharacter.set_stick) against Python's full path driven
    by the scripted joystick (mmrl.rl.policies.JoystickPolicy, arrive off, at the stick's speed)
    whose target is moved before every decision to the character's root + 1000 m along the stick:
    the joystick then asks for the stick's direction in the character frame.

    ``phases``: in turn, ``("stick", (x, z), speed, decisions)``, or ``("target", (dx, dz),
    decisions)``: set_target to the root at the phase's start + (dx, dz), both sides acting with
    the runtime's policy (as drive_both). Obstacle tasks: the env's obstacles and velocities go to
    the runtime before each decision; ``stop_at_done`` ends the drive with the env's episode (a
    collision respawns the obstacles). ``runtime_actions``: the Python side plays the runtime's own
    stick action (bit-identical) rather than the joystick's, which differs from it by float
    rounding (``action_error``): for a compressed controller, whose continuous decisions carry
    rounding on. ``request``, ``compressed``, ``start``: as drive_both.

    Returns per decision both sides' matches and the stick flags, the largest root and pose
    differences per frame, the largest difference between the stick's and the joystick's actions
    (relative to max(1, |action|)), and the root at each phase's start and end."""
    from mmrl.rl.policies import JoystickPolicy

    fp, ch, controller = start_both(path, task, db, config, seed, compressed, start)
    if request:
        fp.set_request(request)
        ch.set_request(request)
    obstacles = hasattr(fp.env, "obstacles")
    out = {"py_matches": [], "rt_matches": [], "sticks": [], "root_error": 0.0, "pose_error": 0.0, "action_error": 0.0,
           "frame_mismatches": 0, "transitions": 0, "phase_roots": [], "stopped": False}
    for phase in phases:
        root0 = np.array(fp.character.root)
        if phase[0] == "stick":
            _, direction, speed, decisions = phase
            d = np.asarray(direction, np.float64) / np.hypot(*direction)
            ch.set_stick(float(direction[0]), float(direction[1]), float(speed))
            joystick = JoystickPolicy(db, speed, layout=fp.env.observation_layout)
        else:
            _, offset, decisions = phase
            target = root0[:2] + np.asarray(offset)
            fp.set_target(*target)
            ch.set_target(*target)
        for _ in range(decisions):
            if obstacles:
                o = fp.env.obstacles(0)
                ch.set_obstacles(*(np.ascontiguousarray(o[k], np.float32)
                                   for k in ("centres", "half_sizes", "angles", "velocities")))
            if phase[0] == "stick":
                r = fp.character.root
                fp.set_target(r[0] + 1000.0 * d[0], r[1] + 1000.0 * d[1])
                joy, ours = joystick.act(fp.obs[None])[0], ch.stick_action()
                out["action_error"] = max(out["action_error"],
                                          float(np.max(np.abs(ours - joy) / np.maximum(1.0, np.abs(joy)))))
                action = ours if runtime_actions else joy
            else:
                action = controller.act(fp.obs)
            step = fp.step(action)
            res = step["res"]
            for k in range(res.frames.size):
                ch.advance_frame()
                out["frame_mismatches"] += int(ch.frame != res.frames[k])
                out["root_error"] = max(out["root_error"], float(np.max(np.abs(np.array(ch.root) - res.roots[k]))))
                out["pose_error"] = max(out["pose_error"],
                                        float(np.max(np.abs(ch.global_positions() - res.positions[k]))))
            decision = ch.last_decision()
            out["py_matches"].append(res.match)
            out["rt_matches"].append(decision["match"])
            out["sticks"].append(decision["stick"])
            out["transitions"] += int(decision["transition"])
            if step["done"]:
                if stop_at_done:
                    out["stopped"] = True
                    break
                fp.continue_from_character(fp.target)
        out["phase_roots"].append((root0, np.array(fp.character.root)))
        if out["stopped"]:
            break
    for key in ("py_matches", "rt_matches", "sticks"):
        out[key] = np.array(out[key])
    return out


def built_artifact(env_var: str, pattern: str, what: str):
    """A file CMake builds (the runtime example, the C interface's library): $env_var, else
    build/*/<pattern> beside the checkout. Missing: a failure in CI, a skip elsewhere."""
    import os
    from pathlib import Path

    import pytest

    root = Path(__file__).resolve().parents[1]
    env = os.environ.get(env_var)
    for path in ([Path(env)] if env else sorted(root.glob(f"build/*/{pattern}"))):
        if path.is_file():
            return path
    if os.environ.get("CI"):
        pytest.fail(f"{pattern} is not built ({what})")
    pytest.skip(f"{pattern} is not built; build it with cmake ({what})")
