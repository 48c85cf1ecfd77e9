"""Options and resolution shared by the commands: where the database comes from, and what both
training backends (``mmrl train``, ``mmrl train --backend rllib``) read and report: ``--set``
overrides, the task's switches, the run directory and the closing lines."""
from __future__ import annotations

import argparse
from dataclasses import fields
from pathlib import Path
from typing import Any, Dict, List

from ..errors import InputError
from ..motion.sources import data_spec, database_from_spec
from ..tasks import Task, get_task, task_names


def add_data_options(p: argparse.ArgumentParser, *, mirror: bool = False) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--data", nargs="+", metavar="DIR|FILE",
                   help="BVH files or directories to build the database from (default: synthetic data)")
    g.add_argument("--db", metavar="FILE", help="a database saved by 'mmrl db build'")
    if mirror:
        p.add_argument("--mirror", action="store_true", help="with --data: add mirrored copies of the clips")


def data_spec_from_args(args: argparse.Namespace) -> Dict[str, Any]:
    return data_spec(db=getattr(args, "db", None), data=getattr(args, "data", None),
                     mirror=bool(getattr(args, "mirror", False)))


def database_from_args(args: argparse.Namespace):
    return database_from_spec(data_spec_from_args(args))


# ---------------------------------------------------------------------- training options (both backends)
def _coerce(value: str, like):
    if isinstance(like, bool):
        if value.lower() in ("1", "true", "yes", "on"):
            return True
        if value.lower() in ("0", "false", "no", "off"):
            return False
        raise InputError(f"--set: expected true or false, got {value!r}")
    try:
        if isinstance(like, int):
            return int(float(value))
        if isinstance(like, tuple):
            return tuple(int(v) for v in value.split(",") if v)
    except ValueError:
        raise InputError(f"--set: cannot read {value!r} as {type(like).__name__}") from None
    if isinstance(like, float) or like is None:
        try:
            return float(value)
        except ValueError:
            return None if value.lower() == "none" else value
    return value


def split_overrides(items, *dataclasses_) -> List[Dict[str, Any]]:
    """KEY=VALUE items -> one dict of overrides per dataclass instance (by field name)."""
    out: List[Dict[str, Any]] = [dict() for _ in dataclasses_]
    for item in items:
        if "=" not in item:
            raise InputError(f"--set expects KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        for d, o in zip(dataclasses_, out):
            if k in {f.name for f in fields(d)}:
                o[k] = _coerce(v, getattr(d, k))
                break
        else:
            names = sorted({f.name for d in dataclasses_ for f in fields(d)})
            raise InputError(f"--set: unknown option {k!r}; options are {', '.join(names)}")
    return out


def apply_values(obj, values: Dict[str, Any]) -> None:
    for k, v in values.items():
        setattr(obj, k, tuple(v) if isinstance(getattr(obj, k), tuple) and v is not None else v)


def task_flag_options(task: Task, args, saved: Dict[str, Any], sets: List[str]) -> Dict[str, Any]:
    """The callback options (a resumed run's, then the task's switches that set them); the
    switches that set task options are appended to ``sets`` as KEY=VALUE. A switch of
    another task is refused."""
    options: Dict[str, Any] = dict(saved.get("callback_options", {})) if saved else {}
    own_flags = {f.flag for f in task.flags}
    for name in task_names():
        for flag in get_task(name).flags:
            if getattr(args, flag.flag.lstrip("-").replace("-", "_")) and flag.flag not in own_flags:
                raise InputError(f"{flag.flag} applies to the {name} task only")
    for flag in task.flags:
        if getattr(args, flag.flag.lstrip("-").replace("-", "_")):
            if flag.target == "callbacks":
                options[flag.option] = flag.value
            else:
                sets.append(f"{flag.option}={flag.value}")
    return options


def resolve_run(task: Task, args, default_out: str):
    """(saved config.json, run directory, data spec): a resumed run's, or a new directory
    (``--out`` or ``default_out``) that must not hold a run yet."""
    from ..runs import RunDir

    if args.resume:
        run = RunDir(args.resume)
        saved = run.config
        if not saved:
            raise InputError(f"{run.path}: no config.json; not a run directory")
        if run.task_name != task.name:
            raise InputError(f"{run.path} holds a '{run.task_name}' run, not '{task.name}'")
        return saved, run.path, run.data_spec
    out = Path(args.out or default_out)
    if (out / "latest.pt").exists():
        raise InputError(f"{out} already holds a run; use --resume {out} or another --out")
    return {}, out, data_spec_from_args(args)


def report_training(steps: int, seconds: float, how: str, row: Dict[str, Any], checkpoint, callbacks) -> None:
    """The lines ``mmrl train`` ends with (either backend)."""
    print(f"trained {steps:,} steps in {seconds:.1f} s ({how}); success {row.get('success_rate', float('nan')):.3f}, "
          f"return {row.get('episode_return', float('nan')):.1f}; checkpoint {checkpoint}")
    for cb in callbacks:
        if hasattr(cb, "describe"):
            print(cb.describe())
