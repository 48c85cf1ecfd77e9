"""``mmrl train TASK`` and ``mmrl plot``: argument parsing only; the work is in
:mod:`mmrl.rl.ppo`, :mod:`mmrl.tasks` and :mod:`mmrl.runs`."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Dict

from ..errors import InputError
from ..rl.quality_log import MatchQualityLog
from ..tasks import Task, get_task, task_names
from ..tasks.options import check_retired
from .common import (add_data_options, apply_run_flags, apply_values, bounded_int, check_ppo_overrides, count,
                     deprecated_alias, positive_float, positive_int, report_training, resolve_run, seed,
                     split_overrides, task_flag_options)


def register_cli(sub) -> None:
    tasks = task_names()
    t = sub.add_parser("train", help="train a policy with PPO",
                       description="Train a policy that writes motion-matching queries. Progress shows on the "
                       "terminal; metrics go to RUN/metrics.csv and TensorBoard (tensorboard --logdir RUN); "
                       "checkpoints to RUN/latest.pt (atomic) and RUN/snapshot_<step>.pt. Tasks: " +
                       "; ".join(f"{n}: {get_task(n).summary}" for n in tasks))
    t.add_argument("task", nargs="?", choices=tasks,
                   help="the task to train (optional with --resume: the run's own)")
    add_data_options(t, mirror=True)
    budget = t.add_mutually_exclusive_group()
    budget.add_argument("--steps", type=positive_int, default=None,
                        help="stop when the run has this many env steps in all (a total, also with --resume; "
                             "default: 1,000,000 unless --seconds)")
    budget.add_argument("--seconds", type=positive_float, default=None,
                        help="stop after this many seconds of training (wall clock)")
    t.add_argument("--seed", type=seed, default=0, help="random seed of the networks, the envs and the episodes")
    t.add_argument("--out", default=None, help="run directory (default: runs/<task>-seed<SEED>)")
    t.add_argument("--resume", metavar="RUN", default=None,
                   help="continue the run in RUN with its own options (changed by any --set; config.json records "
                        "them)")
    t.add_argument("--envs", type=bounded_int(65536), default=None, help="parallel environments (default: 64)")
    t.add_argument("--threads", type=count, default=0, help="C++ env threads, at most 1024 (default: 0, all cores)")
    t.add_argument("--device", default="auto", help="torch device: auto (CUDA when present), cpu, cuda")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a PPOConfig field or a task option, e.g. --set learning_rate=3e-4 "
                        "--set max_steps=150 (repeatable)")
    t.add_argument("--list-options", action="store_true",
                   help="print the task's options (--set KEY=VALUE): each default, range and what it does; then exit")
    t.add_argument("--request-groups", metavar="GROUPS", default=None, dest="request_groups",
                   help="condition one policy on requests over these tag groups of the database, e.g. "
                        "--request-groups style or style,gait (task option request_groups; docs/styles.md): each "
                        "episode draws a request, matching keeps to its clips, and the policy observes it")
    deprecated_alias(t, "--tags", "--request-groups (db build's --tag-file is the tag file)", "request_groups")
    presets = sorted({p for n in tasks for p in get_task(n).presets} | {"paper-rllib"})
    t.add_argument("--preset", choices=presets or None, default=None,
                   help="a task's named set of options; " + "; ".join(
                       f"{n}: {', '.join(get_task(n).presets)}"
                       + (f" (default {get_task(n).default_preset})" if get_task(n).default_preset else "")
                       for n in tasks if get_task(n).presets) +
                   "; paper is the paper's task as written (docs/quality.md, docs/obstacles.md); paper-rllib "
                   "(with --backend rllib) is the paper's task and the authors' RLlib PPO settings on 11 "
                   "workers; --set overrides it")
    r = t.add_argument_group("Ray RLlib (extra mmrl[rllib]; docs/cluster.md)")
    r.add_argument("--backend", choices=("ppo", "rllib"), default=None,
                   help="ppo: mmrl's own trainer (default); rllib: RLlib's PPO on Ray workers, the same run "
                        "directory (a resumed run keeps its backend)")
    r.add_argument("--workers", type=positive_int, default=None, help="rllib: EnvRunner workers (default 1)")
    r.add_argument("--envs-per-worker", type=positive_int, default=None,
                   help="rllib: characters per worker, one C++ vector env (default 32)")
    r.add_argument("--address", default=None,
                   help="rllib: a Ray cluster to join (e.g. HEAD_IP:6379, or 'auto'); default: a local Ray")
    seen = set()
    for name in tasks:
        for flag in get_task(name).flags:
            if flag.flag not in seen:
                seen.add(flag.flag)
                t.add_argument(flag.flag, action="store_true", help=f"{name}: {flag.help}")
    t.set_defaults(func=cmd_train)

    p = sub.add_parser("plot", help="plot a run's learning curves and checkpoint trajectories (PNG)")
    p.add_argument("run", help="a run directory")
    p.add_argument("-o", "--output", default=None, help="output directory (default RUN/plots)")
    p.add_argument("--targets", type=positive_int, default=4, help="targets in the trajectory plot")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the targets")
    p.set_defaults(func=cmd_plot)


# ---------------------------------------------------------------------- options
def options_text(task: Task) -> str:
    """The task's options as ``mmrl train TASK --list-options`` prints them: from the C++ option
    table (name, default, range, doc), then the trainer's own (training_only)."""
    from dataclasses import fields

    cfg = task.default_config()
    lines = [f"{task.name} options (--set KEY=VALUE; defaults before any preset):"]
    for f in fields(cfg):
        info = cfg.option_table.get(f.name)
        doc = info.doc if info else f.metadata.get("doc", "")
        rng = f", {info.range_text()}" if info and info.range_text() else ""
        lines.append(f"  {f.name} = {getattr(cfg, f.name)!r}{rng}: {doc}".rstrip(": "))
    return "\n".join(lines)


def _configs(task: Task, args, saved: Dict[str, Any]):
    """(task config, PPOConfig, callback options) from the task's defaults, a resumed run's
    saved values, the preset, the task's flags and --set, in that order; a new run conditioned
    on requests adds the task's ``request_ppo_defaults`` where the preset and --set are silent."""
    from ..rl import ppo

    task_cfg = task.default_config()
    cfg = ppo.PPOConfig(seed=args.seed)
    apply_values(cfg, dict(task.ppo_defaults))
    if saved:
        try:  # a run that ran a retired option cannot go on without it
            check_retired(type(task_cfg), saved.get("task_config", {}))
        except ValueError as e:
            raise InputError(f"--resume: {e}") from None
        apply_values(task_cfg, {k: v for k, v in saved.get("task_config", {}).items() if hasattr(task_cfg, k)})
        apply_values(cfg, {k: v for k, v in saved.get("ppo", {}).items() if hasattr(cfg, k)})
    sets = list(args.set)
    preset = args.preset if args.preset is not None or saved else task.default_preset
    if preset is not None:
        if preset not in task.presets:
            owners = [n for n in task_names() if args.preset in get_task(n).presets]
            has = f"presets {', '.join(task.presets)}" if task.presets else "no presets"
            raise InputError(f"--preset {preset}: the {task.name} task has {has} "
                             f"({preset} is a preset of the {' and '.join(owners)} task)")
        if saved and args.preset is not None:
            raise InputError("--preset: a resumed run keeps its configuration (change options with --set)")
        sets = [f"{k}={v}" for k, v in task.presets[preset].items()] + sets
    if getattr(args, "request_groups", None):
        if saved:
            raise InputError("--request-groups: a resumed run keeps its request groups")
        sets.append(f"request_groups={args.request_groups}")
    options = task_flag_options(task, args, saved, sets)
    ppo_over, task_over = split_overrides(sets, cfg, task_cfg)
    check_ppo_overrides(ppo_over)
    apply_values(cfg, ppo_over)
    apply_values(task_cfg, task_over)
    if not saved and getattr(task_cfg, "request_groups", ""):
        apply_values(cfg, {k: v for k, v in task.request_ppo_defaults.items() if k not in ppo_over})
    return task_cfg, cfg, options


def cmd_train(args: argparse.Namespace) -> int:
    from ..rl import ppo
    from ..runs import RunDir

    if args.task is None and not args.resume:
        raise InputError(f"train: name the task ({', '.join(task_names())}), e.g. mmrl train plane --seconds 60")
    if getattr(args, "list_options", False):
        if not args.task:
            raise InputError("--list-options: name the task, e.g. mmrl train obstacles --list-options")
        print(options_text(get_task(args.task)))
        return 0
    if args.resume:
        resumed = RunDir(args.resume, require_run=True)
        if args.task is None:
            args.task = resumed.task_name
        saved_backend = resumed.config.get("backend", "ppo")
        if args.backend is not None and args.backend != saved_backend:
            raise InputError(f"{args.resume}: trained with --backend {saved_backend}; resume it with that backend")
        args.backend = saved_backend
    task = get_task(args.task)
    if args.backend == "rllib":
        from .train_rllib import cmd_train_rllib

        return cmd_train_rllib(args, task)
    for name in ("workers", "envs_per_worker", "address"):
        if getattr(args, name) is not None:
            raise InputError(f"--{name.replace('_', '-')} applies to --backend rllib only")
    if args.preset == "paper-rllib":
        raise InputError("--preset paper-rllib is RLlib's trainer: add --backend rllib")
    if args.mirror and not args.data:
        raise InputError("--mirror applies to --data (BVH); a database is mirrored when built: "
                         "mmrl db build DATA --mirror -o DB.npz")
    saved, out, data = resolve_run(task, args, f"runs/{task.name}-seed{args.seed}")
    task_cfg, cfg, options = _configs(task, args, saved)
    apply_run_flags(cfg, args)
    num_envs = args.envs or saved.get("num_envs") or 64

    from ..motion.sources import database_from_spec

    db = database_from_spec(data)
    if task.check_data is not None:
        try:
            task.check_data(db)
        except ValueError as e:
            raise InputError(f"mmrl train {task.name}: {e}") from None
    try:  # the options are the user's: a value the env refuses is bad input
        # The training envs: a task may train with other options than it evaluates with
        # (Task.training_config); config.json records the run's own.
        envs = task.make_vector_env(num_envs, db=db, config=task.train_config(task_cfg), num_threads=args.threads)
    except (ValueError, TypeError) as e:
        raise InputError(f"{task.name} options: {e}") from e
    callbacks = list(task.callbacks(envs, options)) if task.callbacks else []
    callbacks.append(MatchQualityLog(envs))  # last: the task's callbacks keep their checkpoint indices
    policy_factory = _policy_factory(task, envs, cfg.network)
    # config.json always holds the options the run trains with now, so eval and render read them.
    RunDir.create(out, task=task, data=data, num_envs=num_envs, task_config=task_cfg, ppo_config=cfg,
                  callback_options=options, database=db)
    # A run stopped (killed) before its first checkpoint has config.json but no latest.pt: it
    # starts again from step 0 (ppo.train drops the rows it had logged).
    resume = bool(args.resume) and (out / "latest.pt").exists()
    if args.resume and not resume:
        print(f"{out}: no checkpoint yet (the run stopped before its first save); training starts at step 0")
    from ..rl.trained_policy import NonFiniteError

    try:
        result = ppo.train(envs, cfg, out, policy_factory=policy_factory, resume=resume,
                           callbacks=callbacks)
    except NonFiniteError as e:
        raise InputError(f"training diverged ({e}); {out}/latest.pt keeps the last good checkpoint, if any: "
                         "lower learning_rate (--set learning_rate=...)") from None
    finally:
        envs.close()
    report_training(result.global_step, result.wall_s, result.stopped_by, result.last_stats, result.checkpoint,
                    callbacks)
    return 0


def _policy_factory(task: Task, envs, network: str):
    """The task's network factory for ``--set network=NAME`` ("default": the task's own choice)."""
    from ..rl.networks import task_policy_factory

    factory = task_policy_factory(task)
    if factory is None:
        if network != "default":
            raise InputError(f"--set network={network}: the {task.name} task has one network (default)")
        return None
    if network == "default":
        return factory(envs)
    try:
        return factory(envs, network=network)
    except (TypeError, ValueError) as e:
        raise InputError(f"--set network={network}: {e}") from e


def cmd_plot(args: argparse.Namespace) -> int:
    from ..viz.plots import plot_run

    for path in plot_run(Path(args.run), Path(args.output) if args.output else None, num_targets=args.targets,
                         seed=args.seed):
        print(path)
    return 0
