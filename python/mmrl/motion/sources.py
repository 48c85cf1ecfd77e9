"""Where a database comes from: the one place that turns a user's choice into a Database.

Every command and env resolves its database here: an object, a saved ``.npz``, BVH files or
directories, a run's saved *data spec* (``config.json`` ``"data"``), or the package's
synthetic locomotion (generated once into the cache).

A data spec is a small JSON-able dict: ``{"db": FILE}``, ``{"data": [PATHS], "mirror":
bool}`` or ``{"synthetic": VERSION}``, the synthetic data's version (``synth.SYNTH_VERSION``
when the run was made; ``true``, what runs wrote before versions were recorded, and a spec with
no data are version 2). Older runs may hold a bare path or list, also read.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Union

from ..errors import InputError
from .checks import is_database_file
from .database import Database

PathLike = Union[str, os.PathLike]
_DEFAULT_DBS: Dict[int, Database] = {}
#: The synthetic data's version of a run that recorded none (it was made before version 3).
UNRECORDED_SYNTH_VERSION = 2


def default_database(version: Optional[int] = None) -> Database:
    """The package's synthetic locomotion database (generated once into the cache): today's, or
    an earlier ``version`` a run was trained on (``synth.default_dataset_dir``)."""
    from . import synth

    version = synth.SYNTH_VERSION if version is None else int(version)
    if version not in _DEFAULT_DBS:
        _DEFAULT_DBS[version] = Database.from_bvh(synth.default_dataset_dir(version))
    return _DEFAULT_DBS[version]


def resolve_database(db: Union[Database, PathLike, None] = None,
                     data: Union[PathLike, Sequence[PathLike], None] = None, mirror: bool = False) -> Database:
    """A Database from an object, a saved ``.npz``, BVH files/directories, or the default."""
    if isinstance(db, Database):
        return db
    if db is not None:
        return Database.load(db)
    if data is not None:
        return Database.from_bvh(data, mirror=mirror)
    return default_database()


def data_spec(db: Optional[PathLike] = None, data: Optional[Sequence[PathLike]] = None,
              mirror: bool = False) -> Dict[str, Any]:
    """The data spec of a command line's ``--db`` / ``--data`` / ``--mirror`` (absolute paths)."""
    if db:
        return {"db": str(Path(db).resolve())}
    if data:
        return {"data": [str(Path(d).resolve()) for d in data], "mirror": bool(mirror)}
    from .synth import SYNTH_VERSION

    return {"synthetic": SYNTH_VERSION}


def synthetic_version(spec: Dict[str, Any]) -> int:
    """The synthetic data's version a data spec names (``{"synthetic": VERSION}``; ``true`` or no
    data: :data:`UNRECORDED_SYNTH_VERSION`)."""
    v = spec.get("synthetic", True)
    if v is True or v is None:
        return UNRECORDED_SYNTH_VERSION
    from .synth import VERSION_CLIPS

    if isinstance(v, bool) or not isinstance(v, int) or v not in VERSION_CLIPS:
        raise InputError(f"data spec: synthetic data version {v!r} is not one this mmrl makes "
                         f"({', '.join(map(str, sorted(VERSION_CLIPS)))}); a newer mmrl made this run?")
    return v


def database_from_spec(spec: Any) -> Database:
    """The Database a data spec names (see the module docstring)."""
    if isinstance(spec, (str, list)):
        spec = {"data": spec}
    spec = spec if isinstance(spec, dict) else {}
    if spec.get("db"):
        return resolve_database(db=spec["db"])
    if spec.get("data"):
        return resolve_database(data=spec["data"], mirror=bool(spec.get("mirror", False)))
    return default_database(synthetic_version(spec))


def load_any(path: PathLike, **import_options) -> Database:
    """A database from a ``.npz`` file, or built from a BVH file or directory (``import_options``:
    ``Database.from_bvh``'s, e.g. ``up`` and ``fps``)."""
    p = Path(path)
    if p.is_file() and (p.suffix == ".npz" or is_database_file(p)):
        return Database.load(p)
    return Database.from_bvh(p, **import_options)
