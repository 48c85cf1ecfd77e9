"""``mmrl compress``: train the networks of a compressed controller (learned motion matching)."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from .common import (add_data_options, apply_values, database_from_args, output_path, positive_float, positive_int,
                     seed, split_overrides, warn)


def register_cli(sub) -> None:
    c = sub.add_parser("compress", help="train a compressed controller's networks from a database or a run "
                       "(learned motion matching; docs/compressed.md)")
    c.add_argument("source", nargs="?", metavar="RUN_OR_DB",
                   help="a training run directory or a database .npz (or use --db / --data; default: synthetic)")
    add_data_options(c)
    c.add_argument("-o", "--output", default=None, help="output compressed.pt (metrics beside it)")
    c.add_argument("--seconds", type=positive_float, default=None,
                   help="stop after this many seconds of training (default: --iterations only)")
    c.add_argument("--iterations", type=positive_int, default=None,
                   help="the decompressor's iterations (default: 50,000); the stepper's and projector's are "
                        "--set stepper_iterations=N / projector_iterations=N")
    c.add_argument("--resume", nargs="?", const="", default=None, metavar="FILE",
                   help="continue the training saved in FILE (a compressed.pt of mmrl compress)")
    c.add_argument("--stages", default=None, metavar="LIST",
                   help="train these stages of the finished OUTPUT again from fresh networks, with the whole "
                        "budget (comma-separated: decompressor, stepper, projector), e.g. --stages projector "
                        "--seconds 900 --set projector_iterations=80000")
    c.add_argument("--seed", type=seed, default=0, help="random seed of the networks and the batches")
    c.add_argument("--device", default="auto", help="torch device: auto (CUDA when present), cpu, cuda")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    c.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a CompressConfig field, e.g. --set latent=16 --set hidden=256,256")
    c.set_defaults(func=cmd_compress)


def _database(args):
    from ..motion.database import Database
    from ..runs import RunDir

    if args.source is None:
        return database_from_args(args)
    if args.db or args.data:
        raise InputError("compress: give RUN_OR_DB or --db/--data, not both")
    p = Path(args.source)
    if p.is_dir():
        return RunDir(p).database()
    if p.suffix == ".npz":
        return Database.load(p)
    raise InputError(f"{p}: expected a run directory or a database .npz")


def _resume_target(args) -> None:
    """``--resume FILE`` continues FILE; the old spelling, a bare ``--resume`` with ``-o FILE``,
    still works (a run or database given right after it is the source, as it was)."""
    if args.resume is None:
        if args.output is None:
            raise InputError("compress: name the output with -o FILE (or continue one with --resume FILE)")
        return
    old_source = args.resume and args.source is None and (Path(args.resume).is_dir() or args.resume.endswith(".npz"))
    if args.resume == "" or old_source:
        if old_source:
            args.source = args.resume
        warn("a bare --resume is deprecated and goes in the next release: it is now --resume FILE")
        if args.output is None:
            raise InputError("--resume: name the file to continue, --resume FILE")
        args.resume = args.output
    if args.output is not None and Path(args.output) != Path(args.resume):
        raise InputError(f"--resume {args.resume} continues that file; drop -o {args.output}")
    args.output = args.resume


def cmd_compress(args: argparse.Namespace) -> int:
    from ..compress.train import CompressConfig, load_compressed, train_compressed

    _resume_target(args)
    resume = args.resume is not None
    out = output_path(args.output, "--resume" if resume else "-o")
    db = _database(args)
    cfg = CompressConfig(seed=args.seed, device=args.device)
    stages = [x.strip() for x in args.stages.split(",") if x.strip()] if args.stages else None
    from ..compress.networks import STAGES

    for stage in stages or ():
        if stage not in STAGES:
            raise InputError(f"--stages: no stage {stage!r}; the stages are {', '.join(STAGES)}")
    if resume or stages:
        if not out.is_file():
            raise InputError(f"--{'resume' if resume else 'stages'}: {out} does not exist")
        saved = load_compressed(out, db)["config"]
        apply_values(cfg, {k: v for k, v in saved.items() if hasattr(cfg, k)})
    (over,) = split_overrides(args.set, cfg)
    apply_values(cfg, over)
    if args.iterations is not None:
        cfg.iterations = args.iterations
    if out.exists() and not resume and not stages:
        raise InputError(f"{out} exists; continue it with --resume {out}, or pass another -o")
    try:
        res = train_compressed(db, out, cfg, seconds=args.seconds, resume=resume, progress=not args.no_progress,
                               stages=stages)
    except ValueError as e:
        if stages is None:
            raise
        raise InputError(f"--stages: {e}") from None
    if not res.get("iteration"):
        if not resume and not stages:
            out.unlink(missing_ok=True)
        raise InputError(f"compress: the budget ended before the first iteration (setting up takes a few seconds); "
                         f"nothing {'changed' if resume or stages else 'written'}: give more --seconds")
    held = res.get("holdout_joint_error_cm")
    print(f"wrote {out}: {res['iteration']} iterations; joint error {res.get('joint_error_cm', float('nan')):.2f} cm "
          f"on training frames" + ("" if held is None else f", {held:.2f} cm on held-back clips"))
    return 0
