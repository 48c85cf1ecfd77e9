"""Task options, declared once: each task's C++ config lists its options in one table
(``visit`` in cpp/include/mmrl/tasks/*.hpp: name, default, range, one-line doc), and
:func:`task_options` builds the task's Python config dataclass from it. A Python config class
declares only what the C++ core never sees (a trainer's option such as ``train_path_filter``,
listed in ``training_only``); the option's range and doc are ``option_info(config, name)``.

Retired options: an experiment's option that lost is removed from the code, and its C++ config
lists it in ``retired()`` (name -> the value the code now always has; the runtime's loader reads
the same table), which :func:`task_options` copies into the Python config's ``retired``. A saved config that ran it
with that value loads as before; any other value, or a new setting of it, is refused naming it
(the task's docs, "Retired options", say what it did and measured)."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping, NamedTuple

import numpy as np

#: Python's type of each kind of C++ option (a clip-cost table and a list of tag groups are
#: written as text in Python: "PATTERN=COST;..." and "style,gait").
_KINDS = {"int": int, "float": float, "bool": bool, "floats": str, "texts": str}


class OptionInfo(NamedTuple):
    """One row of a C++ option table."""
    name: str
    kind: str
    default: Any
    low: float
    high: float
    low_open: bool
    inf_ok: bool
    doc: str

    def range_text(self) -> str:
        """The range in words ("", ">= 0", "in [1, 30]", ...)."""
        if self.kind not in ("int", "float") or (self.low == -np.inf and self.high == np.inf):
            return ""
        low = f"{self.low:g}"
        if self.high == np.inf:
            return f"{'>' if self.low_open else '>='} {low}" + (" or inf" if self.inf_ok else "")
        return f"in {'(' if self.low_open else '['}{low}, {self.high:g}]"


def _python_default(kind: str, value):
    if kind in ("floats", "texts"):
        return ""
    if kind == "float":
        return float(str(np.float32(value)))  # 0.6, not float32's 0.6000000238
    return _KINDS[kind](value)


def task_options(core_config_type):
    """Class decorator: makes ``cls`` a dataclass whose fields are the options of
    ``core_config_type`` (a ``_core`` config class), in its table's order, with their defaults,
    followed by the fields ``cls`` declares itself (options the C++ core never sees)."""
    table = tuple(OptionInfo(*row) for row in core_config_type.options)

    def wrap(cls):
        own = dict(cls.__dict__.get("__annotations__", {}))
        annotations = {}
        for row in table:
            annotations[row.name] = _KINDS[row.kind]
            setattr(cls, row.name, dataclasses.field(default=_python_default(row.kind, row.default),
                                                     metadata={"doc": row.doc}))
        for name, kind in own.items():
            annotations.setdefault(name, kind)
        cls.__annotations__ = annotations
        cls.core_type = core_config_type
        cls.retired = {k: int(v) if float(v).is_integer() else v for k, v in core_config_type.retired.items()}
        cls.option_table = {row.name: row for row in table}
        return dataclasses.dataclass(cls)

    return wrap


def option_info(config, name: str) -> OptionInfo:
    """The table row of option ``name`` of a task config (class or instance); KeyError for an
    option the C++ core does not have (a trainer's)."""
    return config.option_table[name]


def retired_error(config_type, name: str) -> str:
    """The one message for retired option ``name`` of ``config_type``."""
    return (f"{config_type.task_label} option {name!r} was an experiment's and is retired (the code now always has "
            f"{name}={config_type.retired[name]!r}; docs/obstacles.md, \"Retired options\", says what it measured)")


def check_retired(config_type, values: Mapping[str, Any], every_value: bool = False) -> None:
    """ValueError for a retired option in ``values`` with another value than the code now has
    (``every_value``: with any value, as a new setting is)."""
    for name, now in getattr(config_type, "retired", {}).items():
        if name in values and (every_value or values[name] != now):
            raise ValueError(retired_error(config_type, name))
