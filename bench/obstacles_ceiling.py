"""How much of the stage-10 obstacles task can this character solve at all?

    python bench/obstacles_ceiling.py [--data DIR | --db FILE.npz] [--episodes 200] [--seed 4242]
        [--inflate 0.5] [--run RUN ...]

On stage-10 episodes (targets in a 10 x 10 m square, 100 obstacles) with the obstacles frozen
(speed 0, so a plan made at the start stays valid), it measures:

- reachable: a path exists for the body disc (0.25 m) from the start to within the success
  radius of the target (8-connected free cells of a 5 cm grid);
- straight clear: the straight segment to the target is free;
- joystick: the obstacle-blind joystick (walking speed, straight at the target);
- planner: the same joystick steered at a waypoint 1.2 m down the geodesic distance field of
  the obstacles inflated by ``--inflate`` (full knowledge of the map, planned once);
- each ``--run``: a trained policy (deterministic) on the same episodes.

The policies also run on the real stage 10 (moving obstacles). The gap between "reachable"
and "planner" is what the character's motion (the database's walking turns, no stopping)
costs a controller that knows the whole map; the trained policy sees only its sensors.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"
HALF = 9.0  # meters: the planning grid covers [-HALF, HALF]^2 (targets are within 5 m)


def occupancy(obst: dict, xs: np.ndarray, radius: float) -> np.ndarray:
    """(n, n) bool: grid cells within ``radius`` of any rectangle ([row z][col x])."""
    X, Z = np.meshgrid(xs, xs, indexing="xy")
    occ = np.zeros(X.shape, bool)
    for c, h, a in zip(obst["centres"], obst["half_sizes"], obst["angles"]):
        dx, dz = X - c[0], Z - c[1]
        u = np.cos(a) * dx - np.sin(a) * dz
        v = np.sin(a) * dx + np.cos(a) * dz
        du, dv = np.maximum(np.abs(u) - h[0], 0), np.maximum(np.abs(v) - h[1], 0)
        occ |= du * du + dv * dv <= radius * radius
    return occ


def geodesic(free: np.ndarray, xs: np.ndarray, target: np.ndarray, radius: float) -> np.ndarray:
    """Geodesic distance (cells) from the free cells within ``radius`` of ``target``; inf where unreachable."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    n = len(xs)
    idx = np.arange(n * n).reshape(n, n)
    rows, cols, weights = [], [], []
    for di, dj, w in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, np.sqrt(2)), (1, -1, np.sqrt(2))):
        a = idx[:n - di, max(0, -dj):n - max(0, dj)].ravel()
        b = idx[di:, max(0, dj):n + min(0, dj)].ravel()
        keep = free.ravel()[a] & free.ravel()[b]
        rows.append(a[keep]), cols.append(b[keep]), weights.append(np.full(keep.sum(), w))
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n * n, n * n))
    X, Z = np.meshgrid(xs, xs, indexing="xy")
    sources = idx[((X - target[0]) ** 2 + (Z - target[1]) ** 2 <= radius ** 2) & free]
    if sources.size == 0:
        return np.full((n, n), np.inf)
    return dijkstra(graph.tocsr(), directed=False, indices=sources, min_only=True).reshape(n, n)


def waypoint(dist: np.ndarray, xs: np.ndarray, x: float, z: float, cells: int) -> tuple | None:
    """The point ``cells`` steepest-descent steps down ``dist`` from (x, z), or None off the map."""
    n, pitch = len(xs), xs[1] - xs[0]
    i, j = int((z + HALF) / pitch), int((x + HALF) / pitch)
    if not (0 <= i < n and 0 <= j < n) or not np.isfinite(dist[i, j]):
        return None
    for _ in range(cells):
        window = dist[max(0, i - 1):i + 2, max(0, j - 1):j + 2]
        a, b = np.unravel_index(np.argmin(window), window.shape)
        ni, nj = max(0, i - 1) + a, max(0, j - 1) + b
        if (ni, nj) == (i, j):
            break
        i, j = ni, nj
    return xs[j], xs[i]


class _Act:
    """A policy object for ``first_episodes`` from a function of (env, obs)."""

    def __init__(self, env, fn):
        self.env, self.fn = env, fn

    def act(self, obs, deterministic=True):
        return self.fn(self.env, obs)


def run_episodes(env, act, seed: int) -> np.ndarray:
    """Success of each env's first episode, acting with ``act(env, obs)``."""
    from mmrl.rollout import first_episodes

    return first_episodes(env, _Act(env, act), seed)["success"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--data", default=None, help=f"BVH directory (default {DEFAULT_DATA})")
    src.add_argument("--db", default=None, help="a database saved by 'mmrl db build'")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--inflate", type=float, default=0.5, help="planner's obstacle inflation (meters)")
    ap.add_argument("--pitch", type=float, default=0.05, help="planning grid cell (meters)")
    ap.add_argument("--run", nargs="*", default=[], help="trained obstacles runs to evaluate on the same episodes")
    args = ap.parse_args()

    import mmrl
    from mmrl.rl import ppo
    from mmrl.runs import RunDir
    from mmrl.tasks.curriculum import stage_params
    from mmrl.tasks.obstacles import ObstaclesConfig, ObstaclesVectorEnv
    from mmrl.rl.policies import JoystickPolicy

    db = mmrl.Database.load(args.db) if args.db else mmrl.Database.from_bvh(args.data or DEFAULT_DATA)
    n = args.episodes
    speed, half = stage_params(10)
    cfg = ObstaclesConfig()
    xs = (np.arange(int(2 * HALF / args.pitch)) + 0.5) * args.pitch - HALF
    joystick = JoystickPolicy.preset(db, "joystick")

    def make(config, max_speed):
        env = ObstaclesVectorEnv(n, db=db, config=config, num_threads=0)
        env.set_stage(max_speed, half, 10)
        return env

    # The frozen scenes: reachability, straight paths and the planner's distance fields.
    env = make(cfg, 0.0)
    env.reset(seed=args.seed)
    joystick.bind_layout(env.observation_layout)
    reachable, straight, fields_ = np.zeros(n, bool), np.zeros(n, bool), []
    for i in range(n):
        st, ob = env.env_state(i), env.obstacles(i)
        start, target = np.array([st["x"], st["z"]]), np.asarray(st["target"], float)
        body = ~occupancy(ob, xs, cfg.body_radius)
        d = geodesic(body, xs, target, cfg.success_radius)
        k = (int((start[1] + HALF) / args.pitch), int((start[0] + HALF) / args.pitch))
        reachable[i] = np.isfinite(d[k])
        seg = start + np.linspace(0, 1, 200)[:, None] * (target - start)
        straight[i] = body[((seg[:, 1] + HALF) / args.pitch).astype(int), ((seg[:, 0] + HALF) / args.pitch).astype(int)].all()
        fields_.append(geodesic(~occupancy(ob, xs, args.inflate), xs, target, cfg.success_radius))
    look = int(round(1.2 / args.pitch))

    def planner(env, obs):
        o = obs.copy()
        for i in range(env.num_envs):
            st = env.env_state(i)
            w = waypoint(fields_[i], xs, st["x"], st["z"], look)
            if w is not None:  # steer at the waypoint: its position in the character frame
                dx, dz, c, s = w[0] - st["x"], w[1] - st["z"], np.cos(st["yaw"]), np.sin(st["yaw"])
                o[i, -2:] = (c * dx - s * dz, s * dx + c * dz)
        return joystick.act(o)

    rows = [("reachable (body disc)", reachable.mean(), None), ("straight path clear", straight.mean(), None),
            ("joystick", run_episodes(make(cfg, 0.0), lambda e, o: joystick.act(o), args.seed).mean(),
             run_episodes(make(cfg, speed), lambda e, o: joystick.act(o), args.seed).mean()),
            (f"planner + joystick (inflate {args.inflate} m)", run_episodes(make(cfg, 0.0), planner, args.seed).mean(),
             None)]
    for run in args.run:
        rcfg = RunDir(run).task_config()
        policy = ppo.load_policy(Path(run) / "latest.pt")
        act = lambda e, o: policy.act(o, deterministic=True)  # noqa: E731
        rows.append((f"trained: {run}", run_episodes(make(rcfg, 0.0), act, args.seed).mean(),
                     run_episodes(make(rcfg, speed), act, args.seed).mean()))

    print(f"stage-10 geometry, {n} episodes (seed {args.seed})")
    print(f"{'':<48}{'frozen obstacles':>17}{'moving (stage 10)':>19}")
    for name, frozen, moving in rows:
        print(f"{name:<48}{frozen:>17.3f}{'-' if moving is None else f'{moving:.3f}':>19}")


if __name__ == "__main__":
    main()
