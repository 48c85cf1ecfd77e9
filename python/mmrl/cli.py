"""The ``mmrl`` command line.

Each command module registers its own subcommands through ``register_cli(subparsers)``.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import List, Optional

# Modules that contribute subcommands, in help order. A module that is missing (a partial
# install) is skipped rather than breaking the whole command line.
COMMAND_MODULES = ["mmrl.commands.db", "mmrl.motion.data", "mmrl.commands.train", "mmrl.commands.run",
                   "mmrl.commands.export", "mmrl.commands.view",
                   "mmrl.commands.compress"]


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="mmrl", description="Motion matching + reinforcement learning: train, watch, measure and export "
        "character controllers.")
    parser.add_argument("--version", action="version", version=f"mmrl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name != name:
                raise
            continue
        mod.register_cli(sub)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except user_errors() as e:
        # Bad input: one clear line, no traceback. Anything else is a bug and keeps its traceback.
        print(f"mmrl: error: {e}", file=sys.stderr)
        return 2


def user_errors() -> tuple:
    """The exception types that mean bad input (a file, a directory or an argument), not a bug."""
    from .motion.bvh import BVHError, JointRoleError
    from .motion.data import ChecksumError, DownloadError
    from .motion.database import DatabaseFileError
    from .errors import InputError
    from .rl.ppo import CheckpointError
    from .compress.files import CompressedFileError

    return (InputError, CompressedFileError, BVHError, JointRoleError, DatabaseFileError, CheckpointError, ChecksumError, DownloadError,
            FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError, PermissionError)


if __name__ == "__main__":
    sys.exit(main())
