"""Task options: what every task's config shares about its options beyond the dataclass.

Retired options: an experiment's option that lost is removed from the code, and its config class
lists it in ``retired`` (name -> the value the code now always has). A saved config that ran it
with that value loads as before; any other value, or a new setting of it, is refused naming it
(the task's docs, "Retired options", say what it did and measured)."""
from __future__ import annotations

from typing import Any, Mapping


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
