"""Why do obstacle episodes end in a collision? A per-collision record of stage-10 episodes.

    python bench/obstacles_autopsy.py RUN [--db FILE.npz | --data DIR] [--episodes 2000] [--seed 1000]
        [--k 64] [--set KEY=VALUE ...] [--json OUT.json]

Runs RUN's policy (deterministic; or ``--policy joystick``) on the first episode of each of
``--episodes`` fast-path environments at stage 10 (the episodes ``mmrl.rollout.evaluate_fast``
runs for the same seed), records every environment's state before each step, and for every
episode that ends in a collision reports:

- when: a start lost in the first 0.4 s (12 frames), or later;
- the colliding obstacle (the nearest to the body at the colliding frame, found by replaying
  the step's played frames): its speed, its bearing from the character at the step's start
  (0 deg ahead, 90 to the side, 180 behind), whether it was moving toward the character, and
  whether any of the step's current-map sensors was inside it (it was on the sensor map);
- whether the action's three test points were clear under the run's own hit test (hit radius,
  look-ahead) while the played frames hit;
- whether any of the ``--k`` nearest candidate frames of the step's query (the decision's own
  candidates: valid rows outside the exclude window) had a clear path under the
  collision-aware search's test (``ObstacleVecEnv.path_hits``): over the step's played frames,
  and over the whole 1 s horizon.

How collisions are avoided: every step that does not end its episode is classed by the root's
motion over it, in the character frame at the step's start, while an obstacle is within
``NEAR_M`` of the body (edge to the body disc): *stopped* (slower than ``STOP_SPEED``), *stepped
back* (backward faster than ``BACK_SPEED``), *stepped aside* (sideways faster than
``ASIDE_SPEED`` and faster than forward). The summary gives the share of episodes with each, and
the success rate of those episodes.

``--set`` changes task options for the run (e.g. ``--set path_filter=true``). Prints a table
(docs/obstacles.md has the one for the default policy).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np

EARLY_FRAMES = 12  # 0.4 s at 30 fps
NEAR_M = 1.0       # an obstacle this near the body disc (m) makes a step's motion an avoidance
STOP_SPEED = 0.15  # m/s over the step: stopped (the arrive task's rest speed)
BACK_SPEED = 0.1   # m/s backward over the step: stepped back
ASIDE_SPEED = 0.3  # m/s sideways over the step, and more than forward: stepped aside
AVOIDANCE = ("stopped", "stepped back", "stepped aside")


def avoidance_kinds(root0, root1, seconds: float) -> set:
    """What a step's root motion was, in the character frame at its start (math.hpp: x left, z
    forward): a subset of AVOIDANCE."""
    x0, z0, yaw0 = root0
    dx, dz = root1[0] - x0, root1[1] - z0
    c, sn = math.cos(yaw0), math.sin(yaw0)
    left, forward = (c * dx - sn * dz) / seconds, (sn * dx + c * dz) / seconds
    kinds = set()
    if math.hypot(left, forward) < STOP_SPEED:
        kinds.add("stopped")
    if forward < -BACK_SPEED:
        kinds.add("stepped back")
    if abs(left) > ASIDE_SPEED and abs(left) > abs(forward):
        kinds.add("stepped aside")
    return kinds


def bounce_path(centres: np.ndarray, velocities: np.ndarray, frames: int, dt: float, half: float) -> np.ndarray:
    """Obstacle centres (frames + 1, n, 2) under the env's motion rule (grid.hpp: per frame,
    constant velocity, mirrored at the square's border), frame 0 the given ones."""
    c = centres.astype(np.float32).copy()
    v = velocities.astype(np.float32).copy()
    out = [c.copy()]
    for _ in range(frames):
        c = c + v * np.float32(dt)
        over, under = c > half, c < -half
        c = np.where(over, 2 * half - c, np.where(under, -2 * half - c, c))
        v = np.where(over | under, -v, v)
        out.append(c.copy())
    return np.stack(out)


def rect_distance(points: np.ndarray, centres: np.ndarray, half_sizes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Distance (P, n) from points (P, 2) to rectangles (grid.hpp's frame convention)."""
    d = points[:, None, :] - centres[None, :, :]
    c, s = np.cos(angles)[None], np.sin(angles)[None]
    u = c * d[..., 0] - s * d[..., 1]
    v = s * d[..., 0] + c * d[..., 1]
    du = np.maximum(np.abs(u) - half_sizes[None, :, 0], 0)
    dv = np.maximum(np.abs(v) - half_sizes[None, :, 1], 0)
    return np.sqrt(du * du + dv * dv)


def played_roots(db, root, match: int, frames: int) -> np.ndarray:
    """World (x, z) of the root after each of ``frames`` frames played from ``match`` (decision.hpp)."""
    x, z, yaw = float(root[0]), float(root[1]), float(root[2])
    out = []
    deltas = db.root_deltas
    for k in range(frames):
        dx, dz, dyaw = (float(v) for v in deltas[match + k])
        c, s = math.cos(yaw), math.sin(yaw)
        x, z = x + c * dx + s * dz, z - s * dx + c * dz
        yaw += dyaw
        out.append((x, z))
    return np.asarray(out, np.float64)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", nargs="?", help="a training run directory (its policy, options and database)")
    ap.add_argument("--db", default=None, help="database .npz (default: the run's)")
    ap.add_argument("--data", default=None, help="BVH directory (default: the run's database)")
    ap.add_argument("--policy", choices=("joystick", "joystick-run"), default=None)
    ap.add_argument("--episodes", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--k", type=int, default=64, help="candidate frames tested per decision")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="task option for this run")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--json", default=None, help="write the records and the summary here")
    args = ap.parse_args(argv)

    from mmrl import _core
    from mmrl.commands.common import split_overrides
    from mmrl.motion.database import Database
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.rollout import apply_stage, policy_actions
    from mmrl.runs import RunDir
    from mmrl.tasks import get_task

    task = get_task("obstacles")
    run = RunDir(args.run) if args.run else None
    if args.db:
        db = Database.load(args.db)
    elif args.data:
        db = Database.from_bvh_dir(args.data) if hasattr(Database, "from_bvh_dir") else Database.build(args.data)
    elif run is not None:
        db = run.database()
    else:
        ap.error("give RUN or --db/--data")
    config = run.task_config(task) if run is not None else task.default_config()
    if args.set:
        (values,) = split_overrides(args.set, config)
        config = dataclasses.replace(config, **values)
    if args.policy or run is None:
        policy = JoystickPolicy.preset(db, args.policy or "joystick")
        name = args.policy or "joystick"
    else:
        policy, name = run.policy(), str(args.run)

    n = args.episodes
    env = task.make_vector_env(n, db=db, config=config, num_threads=args.threads)
    apply_stage(task, env, None)
    low = env.single_action_space.low
    high = env.single_action_space.high
    dt = 1.0 / db.fps
    half = float(config.obstacle_square_half)
    body = float(config.body_radius)
    normalized = np.asarray(db.normalized_features, np.float32)
    valid = np.asarray(db.valid_mask, bool)
    valid_rows = np.flatnonzero(valid)
    tree = _core.KDTree(np.ascontiguousarray(normalized[valid_rows]), num_threads=max(args.threads, 0))
    clip_of = np.asarray(db.frame_clip)
    clip_ranges = np.asarray(db.clip_ranges).reshape(-1, 2)
    window = int(_core.MATCH_EXCLUDE_WINDOW)

    obs, _ = env.reset(seed=args.seed)
    done = np.zeros(n, bool)
    records = []
    outcome = np.zeros(n, np.int8)  # 1 success, 2 collision, 3 truncated
    avoided = {kind: np.zeros(n, bool) for kind in AVOIDANCE}  # per episode: any step near an obstacle
    while not done.all():
        live = np.flatnonzero(~done)
        actions = policy_actions(policy, obs, True, env.observation_layout)
        # Before the step: the state, the obstacles, the map's sensors, the action's test, and
        # the k nearest candidates' paths.
        snap = {}
        clipped = np.clip(actions, low, high)
        frames = env.current_frames()
        queries = np.concatenate([normalized[frames[live], :_core.POSE_DIM if hasattr(_core, "POSE_DIM") else 15],
                                  clipped[live]], axis=1).astype(np.float32)
        extra = 2 * window + 2
        idx, _ = tree.query(np.ascontiguousarray(queries), args.k + extra)
        for row, i in enumerate(live):
            st = env.env_state(int(i))
            f = int(frames[i])
            c = int(clip_of[f])
            lo, hi = max(clip_ranges[c, 0], f - window), min(clip_ranges[c, 1], f + window + 1)
            cand = valid_rows[idx[row]]
            cand = cand[(cand < lo) | (cand >= hi)][:args.k]
            first_hits = env._core.path_hits(int(i), np.ascontiguousarray(cand, np.int64))
            hits, _, _ = env.action_hits(int(i), actions[i])
            snap[int(i)] = dict(root=(st["x"], st["z"], st["yaw"]), obstacles=env.obstacles(int(i)),
                                sensors=env.sensor_positions(int(i)).reshape(-1, 2), action_hits=int(hits),
                                first_hits=first_hits, frame=f)
        obs, _, term, trunc, info = env.step(actions)
        ended = (term | trunc) & ~done
        step_frames = env.step_frames
        for i in live:
            i = int(i)
            if ended[i]:
                continue
            s = snap[i]
            ob = s["obstacles"]
            if len(ob["centres"]) == 0:
                continue
            edge = rect_distance(np.array([s["root"][:2]], np.float32), ob["centres"], ob["half_sizes"],
                                 ob["angles"])[0].min() - body
            if edge > NEAR_M:
                continue
            st = env.env_state(i)
            for kind in avoidance_kinds(s["root"], (st["x"], st["z"]), max(int(step_frames[i]), 1) * dt):
                avoided[kind][i] = True
        for i in np.flatnonzero(ended):
            i = int(i)
            if info["success"][i]:
                outcome[i] = 1
                continue
            if trunc[i] and not term[i]:
                outcome[i] = 3
                continue
            outcome[i] = 2
            s = snap[i]
            match, _ = env.last_step_decision(i)
            played = int(env.env_state(i)["step_frames"])
            roots = played_roots(db, s["root"], match, played)
            ob = s["obstacles"]
            path = bounce_path(ob["centres"], ob["velocities"], played, dt, half)
            dist = rect_distance(roots[-1:], path[-1], ob["half_sizes"], ob["angles"])[0]
            k = int(np.argmin(dist))
            x0, z0, yaw0 = s["root"]
            rel = ob["centres"][k] - np.array([x0, z0])
            c, sn = math.cos(yaw0), math.sin(yaw0)
            lx, lz = c * rel[0] - sn * rel[1], sn * rel[0] + c * rel[1]  # math.hpp world_to_local_xz
            bearing = abs(math.degrees(math.atan2(lx, lz)))
            vel = ob["velocities"][k]
            speed = float(np.hypot(*vel))
            approaching = bool(speed > 1e-6 and np.dot(vel, -rel) > 0)
            on_map = bool((rect_distance(s["sensors"], ob["centres"][k:k + 1], ob["half_sizes"][k:k + 1],
                                         ob["angles"][k:k + 1])[:, 0] == 0).any())
            fh = s["first_hits"]
            records.append(dict(
                env=i, episode_frames=int(info["episode_frames"][i]), step_frames=played,
                early=bool(int(info["episode_frames"][i]) <= EARLY_FRAMES), obstacle_speed=speed,
                bearing_deg=bearing, approaching=approaching, on_map=on_map,
                obstacle_distance=float(dist[k]), query_points_clear=s["action_hits"] == 0,
                match=int(match), transition=bool(match != s["frame"]),
                candidate_clear_played=bool(((fh == 0) | (fh > played)).any()),
                candidate_clear_horizon=bool((fh == 0).any()), candidates=int(len(fh))))
        done |= ended
    env.close()

    coll = [r for r in records]
    m = max(len(coll), 1)

    def share(pred):
        return sum(1 for r in coll if pred(r)) / m

    summary = {
        "policy": name, "episodes": n, "seed": args.seed, "options": args.set,
        "success_rate": float(np.mean(outcome == 1)), "collision_rate": float(np.mean(outcome == 2)),
        "truncation_rate": float(np.mean(outcome == 3)), "collisions": len(coll),
        "early (first 0.4 s)": share(lambda r: r["early"]),
        "obstacle moving (> 0.05 m/s)": share(lambda r: r["obstacle_speed"] > 0.05),
        "obstacle speed, mean (m/s)": float(np.mean([r["obstacle_speed"] for r in coll])) if coll else float("nan"),
        "obstacle approaching": share(lambda r: r["approaching"]),
        "bearing: ahead (< 45 deg)": share(lambda r: r["bearing_deg"] < 45),
        "bearing: side (45-135 deg)": share(lambda r: 45 <= r["bearing_deg"] <= 135),
        "bearing: behind (> 135 deg)": share(lambda r: r["bearing_deg"] > 135),
        "on the sensor map": share(lambda r: r["on_map"]),
        "query points clear, played frames hit": share(lambda r: r["query_points_clear"]),
        "the step jumped clips": share(lambda r: r["transition"]),
        f"a clear candidate among the {args.k} nearest (played frames)": share(lambda r: r["candidate_clear_played"]),
        f"a clear candidate among the {args.k} nearest (1 s)": share(lambda r: r["candidate_clear_horizon"]),
    }
    for kind in AVOIDANCE:
        with_it = avoided[kind]
        summary[f"episodes that {kind} near an obstacle"] = float(with_it.mean())
        summary[f"episodes that {kind}: success rate"] = float((outcome[with_it] == 1).mean()) if with_it.any() else float("nan")
    any_kind = np.any([avoided[k] for k in AVOIDANCE], axis=0)
    summary["episodes with any of them"] = float(any_kind.mean())
    summary["episodes with any of them: success rate"] = float((outcome[any_kind] == 1).mean()) if any_kind.any() else float("nan")
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        shown = f"{value:.3f}" if isinstance(value, float) else str(value)
        print(f"{key:<{width}}  {shown}")
    if args.json:
        Path(args.json).write_text(json.dumps({"summary": summary, "records": records}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
