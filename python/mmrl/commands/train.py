"""``mmrl train`` and ``mmrl plot``."""
from __future__ import annotations

import argparse
import json
import os
from dataclasses import asdict, fields
from pathlib import Path

TASKS = ("plane", "obstacles")
#: Snapshots kept for the paper's Figure 4 (trajectories at about 20k, 100k, 533k and 1M steps).
FIGURE4_STEPS = (20_000, 100_000, 533_000, 1_000_000)


def add_data_options(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--data", nargs="+", metavar="DIR|FILE", help="BVH files or directories (default: synthetic data)")
    g.add_argument("--db", metavar="FILE", help="a database saved by 'mmrl db build'")
    p.add_argument("--mirror", action="store_true", help="with --data: add mirrored copies of the clips")


def register_cli(sub) -> None:
    t = sub.add_parser("train", help="train a policy with PPO",
                       description="Train a policy that writes motion-matching queries. Progress shows on the "
                       "terminal; metrics go to RUN/metrics.csv and TensorBoard (tensorboard --logdir RUN); "
                       "checkpoints to RUN/latest.pt (atomic) and RUN/snapshot_<step>.pt.")
    t.add_argument("task", choices=TASKS)
    add_data_options(t)
    budget = t.add_mutually_exclusive_group()
    budget.add_argument("--steps", type=int, default=None, help="env steps to train (default 1,000,000)")
    budget.add_argument("--seconds", type=float, default=None, help="wall-clock training budget")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--out", default=None, help="run directory (default runs/<task>-seed<K>)")
    t.add_argument("--resume", metavar="RUN", default=None, help="continue the run in RUN")
    t.add_argument("--envs", type=int, default=None, help="parallel environments (default 64)")
    t.add_argument("--threads", type=int, default=0, help="C++ env threads (0 = all cores)")
    t.add_argument("--device", default="auto", help="torch device: auto, cpu, cuda")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a PPOConfig field or a task option, e.g. --set learning_rate=3e-4 "
                        "--set max_steps=150 (repeatable)")
    t.add_argument("--preset", choices=("paper", "mmrl"), default=None,
                   help="obstacles: 'paper' (default: the paper's task as written) or 'mmrl' (bonus 1000, hit "
                        "penalty, annealed learning rate; see docs/obstacles.md); --set overrides it")
    t.add_argument("--no-hit-reward", action="store_true", help="obstacles: drop the hit reward (ablation)")
    t.add_argument("--no-curriculum", action="store_true", help="obstacles: start at the hardest stage (ablation)")
    t.set_defaults(func=cmd_train)

    p = sub.add_parser("plot", help="plot a run's learning curves and checkpoint trajectories (PNG)")
    p.add_argument("run", help="a run directory")
    p.add_argument("-o", "--output", default=None, help="output directory (default RUN/plots)")
    p.add_argument("--targets", type=int, default=4, help="targets in the trajectory plot")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=cmd_plot)


def _coerce(value: str, like):
    if isinstance(like, bool):
        if value.lower() in ("1", "true", "yes", "on"):
            return True
        if value.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"--set: expected true or false, got {value!r}")
    if isinstance(like, int):
        return int(float(value))
    if isinstance(like, float) or like is None:
        try:
            return float(value)
        except ValueError:
            return None if value.lower() == "none" else value
    if isinstance(like, tuple):
        return tuple(int(v) for v in value.split(",") if v)
    return value


def split_overrides(items, *dataclasses_):
    """KEY=VALUE items -> one dict of overrides per dataclass instance (by field name)."""
    out = [dict() for _ in dataclasses_]
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        for d, o in zip(dataclasses_, out):
            if k in {f.name for f in fields(d)}:
                o[k] = _coerce(v, getattr(d, k))
                break
        else:
            names = sorted({f.name for d in dataclasses_ for f in fields(d)})
            raise ValueError(f"--set: unknown option {k!r}; options are {', '.join(names)}")
    return out


def _data_spec(args) -> dict:
    if getattr(args, "db", None):
        return {"db": str(Path(args.db).resolve())}
    if getattr(args, "data", None):
        return {"data": [str(Path(d).resolve()) for d in args.data], "mirror": bool(args.mirror)}
    return {"synthetic": True}


def load_database(spec: dict):
    from ..envs import resolve_database

    if spec.get("db"):
        return resolve_database(db=spec["db"])
    if spec.get("data"):
        return resolve_database(data=spec["data"], mirror=spec.get("mirror", False))
    return resolve_database()


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def cmd_train(args: argparse.Namespace) -> int:
    from .. import ppo
    from ..envs import PlaneConfig

    if args.resume:
        out = Path(args.resume)
        saved = json.loads((out / "config.json").read_text())
        task, data_spec = saved["task"], saved["data"]
        if task != args.task:
            raise ValueError(f"{out} holds a '{task}' run, not '{args.task}'")
    else:
        task, data_spec = args.task, _data_spec(args)
        out = Path(args.out or f"runs/{task}-seed{args.seed}")
        if (out / "latest.pt").exists():
            raise FileExistsError(f"{out} already holds a run; use --resume {out} or another --out")
        saved = None

    db = load_database(data_spec)
    if task == "plane":
        from ..envs import PlaneVectorEnv

        task_cfg = PlaneConfig()
        cfg = ppo.PPOConfig(seed=args.seed, snapshot_steps=FIGURE4_STEPS)
    else:
        from ..obstacles import OBSTACLE_MAP_RANGE, ObstaclesConfig

        task_cfg = ObstaclesConfig()
        # The binary sensor maps stay unnormalized. The CNN's update dominates the cost, so
        # torch gets both cores during updates (the env's threads idle then), and each
        # rollout gets 2 epochs of 2 large minibatches (~160 us per env step on 2 cores).
        cfg = ppo.PPOConfig(seed=args.seed, obs_norm_exclude=OBSTACLE_MAP_RANGE, torch_threads=2, update_epochs=2,
                            num_minibatches=2, learning_rate=1e-3)
    if saved is not None:  # a resumed run keeps its configuration
        for k, v in saved["task_config"].items():
            setattr(task_cfg, k, v)
        for k, v in saved["ppo"].items():
            if hasattr(cfg, k):
                setattr(cfg, k, tuple(v) if isinstance(getattr(cfg, k), tuple) else v)
    sets = list(args.set)
    if args.preset is not None:
        if task != "obstacles":
            raise ValueError("--preset applies to the obstacles task")
        if saved is not None:
            raise ValueError("--preset: a resumed run keeps its configuration")
        from ..obstacles import OBSTACLE_PRESETS

        sets = [f"{k}={v}" for k, v in OBSTACLE_PRESETS[args.preset].items()] + sets
    ppo_over, task_over = split_overrides(sets, cfg, task_cfg)
    for k, v in ppo_over.items():
        setattr(cfg, k, v)
    for k, v in task_over.items():
        setattr(task_cfg, k, v)
    if args.steps is not None:
        cfg.total_steps, cfg.max_seconds = args.steps, None
    elif args.seconds is not None:
        cfg.total_steps, cfg.max_seconds = 10**12, args.seconds
    cfg.device = args.device
    cfg.progress = not args.no_progress
    num_envs = args.envs or (saved or {}).get("num_envs") or 64

    callbacks = []
    policy_factory = None
    if task == "plane":
        envs = PlaneVectorEnv(num_envs, db=db, config=task_cfg, num_threads=args.threads)
    else:
        from ..obstacles import Curriculum, ObstaclesVectorEnv, obstacle_policy_factory

        if args.no_hit_reward:
            task_cfg.hit_reward = False
        envs = ObstaclesVectorEnv(num_envs, db=db, config=task_cfg, num_threads=args.threads)
        curriculum = Curriculum(envs, enabled=not args.no_curriculum)
        callbacks.append(curriculum)
        policy_factory = obstacle_policy_factory(envs)

    out.mkdir(parents=True, exist_ok=True)
    if saved is None:
        atomic_write_text(out / "config.json", json.dumps({
            "task": task, "data": data_spec, "num_envs": num_envs, "task_config": asdict(task_cfg),
            "ppo": asdict(cfg)}, indent=2, default=list))
    result = ppo.train(envs, cfg, out, policy_factory=policy_factory, resume=bool(args.resume), callbacks=callbacks)
    s = result.last_stats
    print(f"trained {result.global_step:,} steps in {result.wall_s:.1f} s ({result.stopped_by}); "
          f"success {s.get('success_rate', float('nan')):.3f}, return {s.get('episode_return', float('nan')):.1f}; "
          f"checkpoint {result.checkpoint}")
    if callbacks:
        cur = callbacks[0]
        passed = f"all stages passed at step {cur.complete_step:,}" if cur.complete_step is not None else (
            "all stages passed" if cur.complete else "the last stage not passed yet")
        print(f"curriculum: stage {cur.stage} of {cur.num_stages}; {passed}")
    envs.close()
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from ..plots import plot_run

    for path in plot_run(Path(args.run), Path(args.output) if args.output else None, num_targets=args.targets,
                         seed=args.seed):
        print(path)
    return 0
