"""Atomic file writes, the one helper for the whole package.

A reader (another process, or the next run after a crash or Ctrl-C) sees either the old
file or the complete new one, never a torn mix: the data goes to a temp file in the same
directory (so the rename stays on one file system), is flushed and fsync'ed, then renamed
over the target with ``os.replace`` (atomic on POSIX and Windows), and the directory is
fsync'ed so the rename itself survives a power loss. On any error, including
KeyboardInterrupt, the temp file is removed and the old file is left untouched.

The new file gets the permissions a plain ``open(path, "w")`` would give (0666 minus the
umask), not the 0600 of ``tempfile.mkstemp``.

Temp files are hidden and named ``.<name>.<random>.tmp`` (``atomic_path`` keeps the target's
suffix after ``.tmp``, for writers that pick a format from it). A process killed with SIGKILL
(or a power loss) cannot remove its temp file: it stays, hidden, beside the target; directory
scans skip hidden files, and ``remove_stale_temps`` deletes such leftovers.
"""
from __future__ import annotations

import contextlib
import glob
import os
import tempfile
import time
from pathlib import Path
from typing import IO, Any, Iterator, List, Optional, Union

__all__ = ["atomic_open", "atomic_path", "atomic_write_bytes", "atomic_write_text", "atomic_write_npz",
           "remove_stale_temps"]

PathLike = Union[str, "os.PathLike[str]"]

# Read once at import (os.umask can only be read by setting it).
_UMASK = os.umask(0)
os.umask(_UMASK)


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return  # not supported (e.g. Windows); the rename is still atomic
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems refuse fsync on directories; the rename is still atomic
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_open(path: PathLike, mode: str = "w", *, encoding: Optional[str] = None,
                newline: Optional[str] = None) -> Iterator[IO[Any]]:
    """Open a temp file beside ``path`` for writing; on a clean exit it replaces ``path``.

    ``mode`` is "w"/"wt" (text, ``encoding`` defaults to UTF-8) or "wb" (binary). The
    directory must exist. Example::

        with atomic_open(run_dir / "config.json") as file:
            json.dump(config, file)
    """
    if mode not in ("w", "wt", "wb"):
        raise ValueError(f"atomic_open: mode must be 'w', 'wt' or 'wb', got {mode!r}")
    path = Path(path)
    binary = "b" in mode
    if binary and (encoding is not None or newline is not None):
        raise ValueError("atomic_open: encoding and newline apply to text mode only")
    text_args = {} if binary else {"encoding": encoding or "utf-8", "newline": newline}
    with _atomic_temp(path, ".tmp") as tmp, open(tmp, mode, **text_args) as file:
        yield file
        file.flush()
        os.fsync(file.fileno())


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "wb") as file:
        file.write(data)
    return Path(path)


def atomic_write_text(path: PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see the module docstring); returns the path."""
    with atomic_open(path, "w", encoding=encoding) as file:
        file.write(text)
    return Path(path)


def atomic_write_npz(path: "str | os.PathLike[str]", **arrays) -> Path:
    """``numpy.savez`` of ``arrays`` to ``path``, atomically (nothing partial is ever visible)."""
    import numpy as np

    with atomic_open(path, "wb") as f:
        np.savez(f, **arrays)
    return Path(path)


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """A temp path beside ``path`` ending in ``.tmp`` plus ``path``'s suffix, for writers that
    need a file name (video encoders, matplotlib); on a clean exit it replaces ``path``, on an
    error it is removed."""
    path = Path(path)
    with _atomic_temp(path, f".tmp{path.suffix}") as tmp:
        yield tmp


@contextlib.contextmanager
def _atomic_temp(path: Path, suffix: str) -> Iterator[Path]:
    # The temp name never ends in the target's own suffix for atomic_open (".tmp"), so a scan
    # for "*.bvh" or "*.npz" cannot pick up a torn leftover even if it does not skip hidden files.
    path = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp_name)
        os.chmod(tmp_name, 0o666 & ~_UMASK)
        os.replace(tmp_name, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_name)
        raise
    _fsync_dir(path.parent)


def remove_stale_temps(path: PathLike, min_age_s: float = 0.0) -> List[Path]:
    """Delete the temp files that atomic writes of ``path`` left behind when their process was
    killed (see the module docstring); only those not modified for ``min_age_s`` seconds, so a
    concurrent writer's live temp file survives when ``min_age_s`` exceeds its write time.
    Returns the removed paths."""
    path = Path(path)
    removed = []
    if not path.parent.is_dir():
        return removed
    now = time.time()
    for tmp in path.parent.glob(glob.escape(f".{path.name}.") + "*.tmp*"):
        try:
            if now - tmp.stat().st_mtime >= min_age_s:
                tmp.unlink()
                removed.append(tmp)
        except FileNotFoundError:
            pass  # removed meanwhile (its writer finished)
    return removed


def load_plain_torch_file(path: Path, error_type: type, unreadable: str, map_location: Any = "cpu") -> Any:
    """``torch.load(path, weights_only=True)``: tensors and plain values only, never code. A file
    holding pickled Python objects raises ``error_type`` saying it is refused (naming the object's
    class); any other failure (corrupt, truncated, foreign) raises ``error_type`` with
    ``unreadable`` (formatted with ``path`` and ``error``)."""
    import pickle
    import re

    import torch

    _check_torch_zip(path, error_type, unreadable)
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as error:
        if "Weights only load failed" not in str(error):
            raise error_type(unreadable.format(path=path, error=error)) from error
        found = re.search(r"Unsupported global: GLOBAL (\S+)", str(error))
        what = f" ({found.group(1)})" if found else ""
        raise error_type(f"{path}: refused: it holds pickled Python objects{what}, not only tensors and plain "
                         f"values; mmrl never unpickles them, since loading them could run code") from None
    except Exception as error:  # torch raises several types for truncated or foreign files
        raise error_type(unreadable.format(path=path, error=error)) from error


def _check_torch_zip(path: Path, error_type: type, unreadable: str) -> None:
    # torch reads a record into a buffer of the size the zip directory declares, before any
    # check: a 5.7 kB file declaring a 4 GB record took 4.4 GB (tests/fuzz/fuzz_python.py
    # checkpoint). torch.save writes every record stored, uncompressed, so a record larger than
    # the file itself is a corrupt file; refuse it before torch allocates anything.
    import zipfile

    size = os.path.getsize(path)
    try:
        with zipfile.ZipFile(path) as archive:
            records = archive.infolist()
    except Exception as error:  # zipfile raises BadZipFile, NotImplementedError, struct.error, ...
        raise error_type(unreadable.format(path=path, error=f"not a torch zip file: {error}")) from None
    for record in records:
        if record.compress_type != zipfile.ZIP_STORED:
            raise error_type(f"{path}: corrupt: its record {record.filename!r} is compressed; torch.save "
                             f"stores every record as it is")
        if record.file_size > size:
            raise error_type(f"{path}: corrupt: its record {record.filename!r} declares {record.file_size} bytes "
                             f"in a file of {size} bytes")
