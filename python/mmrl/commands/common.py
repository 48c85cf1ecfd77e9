"""Options and resolution shared by the commands: where the database comes from, and what both
training backends (``mmrl train``, ``mmrl train --backend rllib``) read and report: ``--set``
overrides, the task's switches, the run directory and the closing lines."""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import fields
from pathlib import Path
from typing import Any, Dict, List

from ..errors import InputError
from ..motion.sources import data_spec, database_from_spec
from ..tasks import Task, get_task, task_names
from ..tasks.options import retired_error


# ---------------------------------------------------------------------- values checked where they are read
def read_number(text: str, kind, what: str):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    if kind is int:
        if value != int(value):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r} (not a whole number)")
        return int(value)
    return value


def _in_range(text: str, kind, what: str, ok, expected: str):
    """``text`` read as ``kind`` (:func:`read_number`, naming ``what``), refused as not ``expected``
    unless ``ok(value)``."""
    v = read_number(text, kind, what)
    if not ok(v):
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return v


def positive_int(text: str, high: int = 10**12) -> int:
    """argparse type: a whole number 1..``high`` (``1e6`` reads as 1000000)."""
    return _in_range(text, int, "a whole number >= 1", lambda v: 1 <= v <= high, f"a whole number from 1 to {high:,}")


def bounded_int(high: int):
    """argparse type: a whole number 1..``high`` (environments, episodes: beyond it is a typo)."""
    return lambda text: positive_int(text, high)


def seed(text: str) -> int:
    """argparse type: a random seed, 0 to 2**32 - 1."""
    return _in_range(text, int, "a seed, a whole number from 0 to 4294967295", lambda v: 0 <= v < 2**32,
                     "a seed from 0 to 4294967295")


def count(text: str, high: int = 1024) -> int:
    """argparse type: a whole number 0..``high``."""
    return _in_range(text, int, "a whole number >= 0", lambda v: 0 <= v <= high, f"a whole number from 0 to {high}")


def positive_float(text: str, high: float = 1e7) -> float:
    """argparse type: a finite number in (0, ``high``] (seconds: 1e7 is four months)."""
    return _in_range(text, float, "a number > 0", lambda v: 0 < v <= high, f"a number > 0 and at most {high:g}")


def nonnegative_float(text: str, high: float = 1e7) -> float:
    """argparse type: a finite number in [0, ``high``] (0 switches a measurement off)."""
    return _in_range(text, float, "a number >= 0", lambda v: 0 <= v <= high, f"a number from 0 to {high:g}")


def port(text: str) -> int:
    """argparse type: a TCP port, 0 (any free one) to 65535."""
    return _in_range(text, int, "a port number 0-65535", lambda v: 0 <= v <= 65535, "a port number 0-65535")


def output_path(path, flag: str, suffixes=()) -> Path:
    """An output file named on the command line: its folder is created (as in every command),
    and a folder or a wrong extension is refused naming ``flag``."""
    out = Path(path)
    if out.is_dir():
        raise InputError(f"{flag} {out}: a folder; name the file to write")
    if suffixes and out.suffix.lower() not in suffixes:
        raise InputError(f"{flag} {out}: the file name must end in {' or '.join(suffixes)}")
    if out.parent.exists() and not out.parent.is_dir():
        raise InputError(f"{flag} {out}: {out.parent} is a file, not a folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    return out


def warn(message: str) -> None:
    """One line on stderr: ``mmrl: warning: ...``."""
    print(f"mmrl: warning: {message}", file=sys.stderr, flush=True)


class _Deprecated(argparse.Action):
    """An old spelling of an option: stores into the new one's dest and says so once."""

    def __init__(self, option_strings, dest, new: str = "", **kwargs):
        self.new = new
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        note = self.new(values) if callable(self.new) else f"it is now {self.new}"
        warn(f"{option_string} is deprecated and goes in the next release: {note}")
        if self.nargs == 0:
            values = True
        if isinstance(getattr(namespace, self.dest, None), list) and not isinstance(values, list):
            values = getattr(namespace, self.dest) + [values]
        setattr(namespace, self.dest, values)


def deprecated_alias(p: argparse.ArgumentParser, old: str, new, dest: str, **kwargs) -> None:
    """``old`` (hidden from --help) as a deprecated spelling of the option whose dest is ``dest``;
    ``new``: its new spelling, or a function of the value that says what to do instead."""
    p.add_argument(old, dest=dest, action=_Deprecated, new=new, help=argparse.SUPPRESS, default=argparse.SUPPRESS,
                   **kwargs)


def add_data_options(p: argparse.ArgumentParser, *, mirror: bool = False) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--data", nargs="+", metavar="DIR|FILE",
                   help="BVH files or folders to build the database from (default: the synthetic data)")
    g.add_argument("--db", metavar="FILE", help="a database file made by 'mmrl db build'")
    if mirror:
        p.add_argument("--mirror", action="store_true", help="with --data: add mirrored copies of the clips")


def data_spec_from_args(args: argparse.Namespace) -> Dict[str, Any]:
    return data_spec(db=getattr(args, "db", None), data=getattr(args, "data", None),
                     mirror=bool(getattr(args, "mirror", False)))


def database_from_args(args: argparse.Namespace):
    return database_from_spec(data_spec_from_args(args))


def run_database(run, args: argparse.Namespace):
    """A run's database, or the one ``--db`` / ``--data`` name (which must have the run's skeleton)."""
    if getattr(args, "db", None) or getattr(args, "data", None):
        db = database_from_args(args)
        run.check_database(db, "--db" if args.db else "--data")
        return db
    return run.database()


# ---------------------------------------------------------------------- training options (both backends)
def _coerce(value: str, like, optional: bool = False):
    """``value`` read as the type of ``like`` (ValueError saying what was expected); "none" is
    None only for an ``optional`` field (or one that is None now)."""
    if isinstance(like, bool):
        if value.lower() in ("1", "true", "yes", "on"):
            return True
        if value.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError("expected true or false")
    if isinstance(like, int):
        try:
            number = float(value)
        except ValueError:
            raise ValueError("expected a whole number") from None
        if not math.isfinite(number) or number != int(number):
            raise ValueError("expected a whole number")
        return int(number)
    if isinstance(like, tuple):
        try:
            return tuple(int(v) for v in value.split(",") if v)
        except ValueError:
            raise ValueError("expected whole numbers separated by commas") from None
    if isinstance(like, float) or like is None:
        try:
            number = float(value)
        except ValueError:
            if value.lower() == "none" and (optional or like is None):
                return None  # an optional number (RLlib's grad_clip=None)
            if isinstance(like, float):
                raise ValueError("expected a number") from None
            return value  # an optional field's text
        if math.isnan(number):
            raise ValueError("expected a number, got NaN")
        return number
    return value


def split_overrides(items, *dataclasses_) -> List[Dict[str, Any]]:
    """KEY=VALUE items -> one dict of overrides per dataclass instance (by field name)."""
    out: List[Dict[str, Any]] = [dict() for _ in dataclasses_]
    for item in items:
        if "=" not in item:
            raise InputError(f"--set expects KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        for d, o in zip(dataclasses_, out):
            field_types = {f.name: str(f.type) for f in fields(d)}
            if k in field_types:
                try:
                    o[k] = _coerce(v, getattr(d, k), optional="Optional" in field_types[k] or "None" in field_types[k])
                except ValueError as e:
                    raise InputError(f"--set {k}={v}: {e}, got {v!r}") from None
                break
        else:
            for d in dataclasses_:
                if k in getattr(d, "retired", {}):
                    raise InputError(f"--set {k}: {retired_error(type(d), k)}")
            names = sorted({f.name for d in dataclasses_ for f in fields(d)})
            raise InputError(f"--set: unknown option {k!r}; options are {', '.join(names)}")
    return out


#: --set PPO fields that command-line flags own, and the flag to use.
FLAG_OWNED = {"device": "--device", "max_seconds": "--seconds", "total_steps": "--steps", "seed": "--seed",
              "progress": "--no-progress"}
#: Ranges of --set PPO fields: (low, high, low inclusive).
PPO_RANGES = {"learning_rate": (0, 10, False), "gamma": (0, 1, False), "gae_lambda": (0, 1, True),
              "clip_coef": (0, 10, False), "ent_coef": (0, 10, True), "vf_coef": (0, 100, True),
              "max_grad_norm": (0, 1e6, False), "num_steps": (1, 10**6, True), "update_epochs": (1, 1000, True),
              "num_minibatches": (1, 10**6, True), "log_interval": (1, 10**9, True),
              "checkpoint_interval_steps": (1, 10**12, True), "torch_threads": (1, 1024, True),
              "obs_clip": (0, 1e9, False), "target_kl": (0, 100, False)}


def check_ppo_overrides(values: Dict[str, Any]) -> None:
    """InputError for a --set PPO value out of its range, or one a flag owns."""
    for k, v in values.items():
        if k in FLAG_OWNED:
            raise InputError(f"--set {k}: use {FLAG_OWNED[k]} instead")
        if k in PPO_RANGES and v is not None:
            lo, hi, closed = PPO_RANGES[k]
            if not ((lo <= v if closed else lo < v) and v <= hi):
                raise InputError(f"--set {k}={v}: expected a value {'from' if closed else 'above'} {lo:g} "
                                 f"up to {hi:g}")
        if k == "hidden" and (not v or min(v) < 1):
            raise InputError(f"--set hidden={','.join(map(str, v))}: expected layer widths >= 1, e.g. 64,64")


def add_deploy_set(p: argparse.ArgumentParser) -> None:
    """``--set KEY=VALUE`` of the commands that run a trained controller (eval, render, export-bvh,
    export, play): a task option for this command only (see :func:`deploy_config`)."""
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a task option for this command only, the run's own kept, e.g. transition_cost=150 "
                        "(repeatable; mmrl train TASK --list-options lists them)")


def deploy_config(task: Task, config, items: List[str], db, trained: bool = True):
    """``config`` with the ``--set`` items applied, checked by building one env over ``db``: how
    a controller is deployed (its search, its transition cost), not how it trained. InputError
    naming the option for an unknown, retired or out-of-range one, and (``trained``: a trained
    policy runs) for one that would change what the policy observes or how its action is read."""
    if not items:
        return config
    (values,) = split_overrides(items, config)
    for k, v in values.items():
        if trained and k in config.policy_inputs and v != getattr(config, k):
            raise InputError(f"--set {k}: the policy was trained with {k}={getattr(config, k)!r}, and what it "
                             f"observes or how its action is read cannot change at deployment")
    config = config.replace(**values)
    try:
        task.make_vector_env(1, db=db, config=config, num_threads=1)
    except (ValueError, TypeError) as e:
        raise InputError(f"--set: {task.name} options: {e}") from None
    return config


def apply_run_flags(cfg, args) -> None:
    """The flags both training backends share, on their config: the budget (``--steps`` or
    ``--seconds``), ``--device`` and ``--no-progress``."""
    if args.steps is not None:
        cfg.total_steps, cfg.max_seconds = args.steps, None
    elif args.seconds is not None:
        cfg.total_steps, cfg.max_seconds = 10**12, args.seconds
    cfg.device = args.device
    cfg.progress = not args.no_progress


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
        run = RunDir(args.resume, require_run=True)
        saved = run.config
        if run.task_name != task.name:
            raise InputError(f"{run.path} holds a '{run.task_name}' run, not '{task.name}'")
        return saved, run.path, run.data_spec
    out = Path(args.out or default_out)
    if (out / "latest.pt").exists():
        raise InputError(f"{out} already holds a run; continue it with --resume {out}, or pass another --out")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: a file, not a folder")
    return {}, out, data_spec_from_args(args)


STOP_REASONS = {"steps": "the step budget (--steps) is done", "seconds": "the time budget (--seconds) is used up"}


def report_training(steps: int, seconds: float, how: str, row: Dict[str, Any], checkpoint, callbacks) -> None:
    """The lines ``mmrl train`` ends with (either backend)."""
    success = row.get("success_rate", float("nan"))
    outcome = ("no training episode has ended yet" if not math.isfinite(success) else
               f"{100 * success:.1f}% of the last iteration's training episodes succeeded")
    print(f"trained {steps:,} steps in {seconds:.1f} s and stopped: {STOP_REASONS.get(how, how)}; {outcome}")
    print(f"saved {checkpoint}; next: mmrl eval {Path(checkpoint).parent}")
    for cb in callbacks:
        if hasattr(cb, "describe"):
            print(cb.describe())
