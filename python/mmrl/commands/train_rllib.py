"""``mmrl train TASK --backend rllib``: argument handling only; the work is in
:mod:`mmrl.integrations.rllib`."""
from __future__ import annotations

import argparse
from typing import Any, Dict

from ..errors import InputError
from ..tasks import Task
from .common import apply_run_flags, apply_values, report_training, resolve_run, split_overrides, task_flag_options

# Our trainer's option names for the knobs RLlib also has (a task preset may set them).
PPO_TO_RLLIB = {"gamma": "gamma", "learning_rate": "lr", "anneal_lr": "anneal_lr", "gae_lambda": "lambda_",
                "clip_coef": "clip_param", "ent_coef": "entropy_coeff", "update_epochs": "num_epochs",
                "num_minibatches": "num_minibatches", "num_steps": "rollout_fragment_length",
                "torch_threads": "torch_threads", "snapshot_steps": "snapshot_steps", "init_log_std": "init_log_std",
                "max_grad_norm": "grad_clip", "obs_norm_exclude": "obs_filter_exclude", "seed": "seed"}


def ppo_settings(values) -> Dict[str, Any]:
    """Our trainer's options as RLlibConfig fields (those RLlib has; the rest have no knob here)."""
    return {PPO_TO_RLLIB[k]: v for k, v in dict(values).items() if k in PPO_TO_RLLIB}


def _configs(task: Task, args: argparse.Namespace, saved: Dict[str, Any]):
    """(task config, RLlibConfig, callback options) from the defaults, a resumed run's saved
    values, the preset (a task preset, or paper-rllib), the task's flags and --set."""
    from ..integrations.rllib import RLLIB_PRESETS, RLlibConfig

    task_cfg = task.default_config()
    cfg = RLlibConfig(seed=args.seed)
    apply_values(cfg, ppo_settings(task.ppo_defaults))  # what the task trains best with, in RLlib's names
    if saved:
        apply_values(task_cfg, {k: v for k, v in saved.get("task_config", {}).items() if hasattr(task_cfg, k)})
        apply_values(cfg, {k: v for k, v in saved.get("rllib", {}).items() if hasattr(cfg, k)})
        if args.preset is not None:
            raise InputError("--preset: a resumed run keeps its configuration (change options with --set)")
    preset = args.preset if args.preset is not None or saved else task.default_preset
    sets = []
    if preset == "paper-rllib":
        sets += [f"{k}={v}" for k, v in task.presets.get("paper", {}).items()]
        sets += [f"{k}={v}" for k, v in RLLIB_PRESETS["paper-rllib"].items()]
    elif preset is not None:
        if preset not in task.presets:
            raise InputError(f"--preset {preset}: the {task.name} task has presets "
                             f"{', '.join(list(task.presets) + ['paper-rllib'])}")
        for k, v in task.presets[preset].items():
            if hasattr(task_cfg, k):
                sets.append(f"{k}={v}")
            elif k in PPO_TO_RLLIB:
                sets.append(f"{PPO_TO_RLLIB[k]}={v}")
            # Other trainer options of the preset have no RLlib knob here.
    options = task_flag_options(task, args, saved, sets)
    rllib_over, task_over = split_overrides(sets + list(args.set), cfg, task_cfg)
    apply_values(cfg, rllib_over)
    apply_values(task_cfg, task_over)
    return task_cfg, cfg, options


def cmd_train_rllib(args: argparse.Namespace, task: Task) -> int:
    try:
        from ..integrations.rllib import RLlibRun, WorkerLost
    except ImportError as e:
        raise InputError(f"--backend rllib: {e}") from None
    from ..runs import RunDir
    from ..motion.sources import database_from_spec

    saved, out, data = resolve_run(task, args, f"runs/{task.name}-rllib-seed{args.seed}")
    task_cfg, cfg, options = _configs(task, args, saved)
    apply_run_flags(cfg, args)
    if args.workers is not None:
        cfg.workers = args.workers
    if args.envs_per_worker is not None:
        cfg.envs_per_worker = args.envs_per_worker
    try:
        cfg.check()
    except ValueError as e:
        raise InputError(str(e)) from None
    if args.address:
        from ..integrations.rllib.trainer import check_reachable

        check_reachable(args.address)  # before anything is written
    db = database_from_spec(data)
    callbacks = list(task.callbacks(None, options)) if task.callbacks else []
    RunDir.create(out, task=task, data=data, num_envs=max(cfg.workers, 1) * cfg.envs(),
                  task_config=task_cfg, ppo_config=cfg, callback_options=options, database=db, backend="rllib")
    import ray

    started_here = not ray.is_initialized()
    run = None
    try:
        run = RLlibRun(task, db, task_cfg, cfg, out, callbacks=callbacks, address=args.address,
                       resume=bool(args.resume))
        row = run.train()
    except WorkerLost as e:
        raise InputError(f"{e}; resume with: mmrl train {task.name} --resume {out}") from None
    finally:
        if run is not None:
            run.stop()
        if started_here:
            ray.shutdown()
    report_training(run.global_step, run.wall_s, f"its budget is used up (RLlib, {cfg.workers} workers x {cfg.envs()} "
                    "envs)", row,
                    out / "latest.pt", callbacks)
    return 0
