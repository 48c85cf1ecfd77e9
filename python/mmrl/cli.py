"""The ``mmrl`` command line.

Each command module registers its own subcommands through ``register_cli(subparsers)``.
Bad input (a wrong argument, file or value) ends in one line, ``mmrl: error: ...``, and exit
code 2, whether argparse or a command finds it; warnings are one line, ``mmrl: warning: ...``.
Anything else is a bug and keeps its traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import warnings
from typing import List, Optional

# Modules that contribute subcommands, in help order. A module that is missing (a partial
# install) is skipped rather than breaking the whole command line.
COMMAND_MODULES = ["mmrl.commands.db", "mmrl.motion.data", "mmrl.commands.train", "mmrl.commands.run",
                   "mmrl.commands.export", "mmrl.commands.view",
                   "mmrl.commands.compress"]


class HelpFormatter(argparse.HelpFormatter):
    """Every option shows its default (unless its help already says it, or it has none)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (action.option_strings and "default" not in text and default not in (None, False, [], "", argparse.SUPPRESS)
                and action.nargs != 0):
            text += f" (default: {default})"
        return text


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors, worded as every other: ``mmrl: error: ... (see mmrl train --help)``, exit 2."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # argparse's own: usage lines first, then the error
        self.exit(2, f"mmrl: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = Parser(
        prog="mmrl", description="Motion matching + reinforcement learning: train, watch, measure and export "
        "character controllers. Start with: mmrl train plane --data YOUR_BVH_FOLDER --seconds 60")
    parser.add_argument("--version", action="version", version=f"mmrl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
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


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    from .commands.common import warn

    warn(str(message))


def main(argv: Optional[List[str]] = None) -> int:
    parser = build_parser()
    with warnings.catch_warnings():
        # The data's warnings are for the person at the terminal: one line each, never an error.
        from .motion.bvh import MotionImportWarning

        warnings.filterwarnings("always", category=MotionImportWarning)
        warnings.showwarning = _one_line_warning
        return _run(parser, argv)


def _run(parser: argparse.ArgumentParser, argv: Optional[List[str]]) -> int:
    try:
        try:
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help and --version exit as argparse does; a bad argument returns 2
            if e.code == 2:
                return 2
            raise
        return int(args.func(args) or 0)
    except BrokenPipeError:  # `mmrl db info | head`: the reader left; nothing to say
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except KeyboardInterrupt as e:
        saved = getattr(e, "saved", None)
        print("interrupted" + (f"; {saved}" if saved else ""), file=sys.stderr)
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

    return (InputError, CompressedFileError, BVHError, JointRoleError, DatabaseFileError,
            CheckpointError, ChecksumError, DownloadError,
            FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError, PermissionError)


if __name__ == "__main__":
    sys.exit(main())
