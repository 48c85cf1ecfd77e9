"""Exceptions that mean "the input is wrong", as opposed to a bug.

The command line prints these as one line (``mmrl: error: ...``, exit code 2); anything
else keeps its traceback, so a bug in mmrl is never disguised as bad input.
"""
from __future__ import annotations


class InputError(ValueError):
    """Bad user input: an argument, a file or a directory. The message names it."""


class MissingExtraError(InputError):
    """An optional feature's dependency is not installed (``pip install 'mmrl[EXTRA]'``)."""


def require_extra(module: str, extra: str, feature: str):
    """Import ``module`` for ``feature``, or raise MissingExtraError naming the extra to install."""
    import importlib

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name is None or not module.startswith(e.name.split(".")[0]):
            raise
        raise MissingExtraError(f"{feature} needs the {module.split('.')[0]} package: "
                                f"pip install 'mmrl[{extra}]'") from e
