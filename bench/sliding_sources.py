"""Where a controller's foot sliding with IK off comes from: how soon after a transition, and in
which kind of motion, next to the raw mocap's own sliding in each kind.

    python bench/sliding_sources.py RUN [--data DIR ... | --db FILE.npz] [--episodes 50] [--seed 1000]
        [--stage 10] [--policy run|joystick|joystick-run] [--set KEY=VALUE ...]

Plays ``--episodes`` full-path episodes of RUN's task (IK and inertialization on, as ``mmrl
eval``; the animated feet before IK are what is measured) and pools every foot-sliding sample (a
foot in contact on two consecutive frames: ``mmrl.metrics.foot_contact_speeds``) by

- the frames since the last transition (the first frame played after a decision that did not
  continue its clip is 1): the inertialization blend hides a transition's pose jump over these
  frames, moving feet that stand;
- the kind of motion of the database frame shown (its +30-frame trajectory sample, as
  ``mmrl.motion.kinds``: idle, turning in place, sideways, backwards; else forward, or running
  above 2 m/s), with the raw mocap's sliding over the frames of that kind
  (``mmrl.metrics.raw_mocap_floor``).

Prints two markdown tables (docs/obstacles.md has the one for the LAFAN1 policies).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

SINCE_BINS = ((1, 3), (4, 6), (7, 12), (13, None))  # frames since the last transition, inclusive
RUN_SPEED = 2.0  # m/s over the next second: running


def frame_kinds(db) -> np.ndarray:
    """(num_frames,) the kind of each frame (``mmrl.motion.kinds``'s rules; forward otherwise)."""
    from mmrl import _core
    from mmrl.motion import kinds

    f = np.asarray(db.features, np.float64)
    p, d = _core.TRAJECTORY_POSITION_COLUMNS[2], _core.TRAJECTORY_DIRECTION_COLUMNS[2]
    x, z = f[:, p], f[:, p + 1]
    dist = np.hypot(x, z)
    turn = np.degrees(np.abs(np.arctan2(f[:, d], f[:, d + 1])))
    moving = dist >= kinds.IDLE_METERS
    out = np.full(db.num_frames, "forward", object)
    out[dist > RUN_SPEED] = "running"  # the +30-frame sample is one second ahead at 30 fps
    out[moving & (np.abs(x) > np.abs(z))] = "sideways"
    out[moving & (z < -np.abs(x))] = "backwards"
    out[(turn > kinds.TURN_IN_PLACE_DEGREES) & (dist < kinds.TURN_IN_PLACE_METERS)] = "turn in place"
    out[~moving] = "idle"
    return out


def frames_since_transition(transitions: np.ndarray, frames: int, frames_per_step: int) -> np.ndarray:
    """(frames,) for each shown frame t >= 1 of a recording, the frames since the last
    transition (1 on the first frame a transition's step plays); a large number before any."""
    since = np.full(frames, 1 << 20, np.int64)
    last = None
    for t in range(1, frames):
        step = (t - 1) // frames_per_step
        if (t - 1) % frames_per_step == 0 and step < len(transitions) and transitions[step]:
            last = t
        if last is not None:
            since[t] = t - last + 1
    return since


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a training run directory")
    ap.add_argument("--data", nargs="*", default=None, help="BVH data (default: the run's database)")
    ap.add_argument("--db", default=None, help="database .npz")
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--stage", type=int, default=None, help="curriculum stage (default: the task's last)")
    ap.add_argument("--policy", default="run", choices=("run", "joystick", "joystick-run"))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)

    from mmrl import metrics
    from mmrl.commands.common import split_overrides
    from mmrl.motion.database import Database
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import FullPath, policy_actions
    from mmrl.runs import RunDir

    run = RunDir(args.run, require_run=True)
    task = run.task
    db = Database.load(args.db) if args.db else Database.from_bvh(args.data) if args.data else run.database()
    cfg = run.task_config(task)
    for item in args.set:
        (values,) = split_overrides(item.split(","), cfg)
        cfg = cfg.replace(**values)
    policy = run.policy() if args.policy == "run" else JoystickPolicy.preset(db, args.policy)
    kind_of = frame_kinds(db)
    fp = FullPath(task, db, config=cfg, stage=args.stage, seed=args.seed)
    speeds, since, kinds = [], [], []
    episodes = 0
    while episodes < args.episodes:
        out = fp.step(policy_actions(policy, fp.obs[None], layout=fp.env.observation_layout)[0])
        if not out["done"]:
            continue
        episodes += 1
        rec = fp.last_recording
        feet, contacts = rec["animated_feet"], np.asarray(rec["contacts"], bool)
        n = feet.shape[0]
        s = frames_since_transition(np.asarray(rec["transitions"], bool), n, cfg.frames_per_step)
        shown = np.asarray(rec["frames"])
        for side in range(2):
            both = np.flatnonzero(contacts[1:, side] & contacts[:-1, side]) + 1
            d = feet[both, side] - feet[both - 1, side]
            speeds.append(100.0 * db.fps * np.hypot(d[:, 0], d[:, 2]))
            since.append(s[both])
            kinds.append(kind_of[shown[both]])
    v, s, k = np.concatenate(speeds), np.concatenate(since), np.concatenate(kinds)
    print(f"{args.run} ({args.policy}{', ' + ', '.join(args.set) if args.set else ''}): {args.episodes} "
          f"full-path episodes, {v.size} contact samples, IK-off sliding {v.mean():.1f} cm/s\n")
    print("| frames since the last transition | share of the samples | sliding IK off (cm/s) |")
    print("|---|---:|---:|")
    for lo, hi in SINCE_BINS:
        m = (s >= lo) & ((s <= hi) if hi else True)
        label = f"{lo}-{hi}" if hi else f"{lo} or more (or none yet)"
        print(f"| {label} | {m.mean():.2f} | {v[m].mean() if m.any() else 0:.1f} |")
    print("\n| shown frame's kind | share of the samples | sliding IK off (cm/s) | raw mocap, frames of that kind |")
    print("|---|---:|---:|---:|")
    valid = np.asarray(db.valid_mask, bool)
    for kind in ("idle", "turn in place", "sideways", "backwards", "forward", "running"):
        m = k == kind
        raw = metrics.raw_mocap_floor(db, only=(kind_of == kind) & valid)["foot_sliding_cm_per_s"]
        print(f"| {kind} | {m.mean():.2f} | {v[m].mean() if m.any() else 0:.1f} | {raw:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
