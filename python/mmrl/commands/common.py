"""Options and resolution shared by the commands: where the database comes from."""
from __future__ import annotations

import argparse
from typing import Any, Dict

from ..motion.sources import data_spec, database_from_spec


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
