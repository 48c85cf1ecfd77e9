"""The exported controller file (``.mmrl``) that the C++ runtime loads (docs/runtime.md).

One little-endian binary file: a 64-byte header, a table of named, typed, checksummed
sections, and the sections' bytes, each 64-byte aligned. Sections hold the database (the
skeleton, every frame's local pose and root motion, the features and their normalization,
the clip ranges and the valid mask), the policy (layers, observation normalization, action
rescaling) and the task's and the character's constants as (name, value) pairs. The format
is written down field by field in docs/runtime.md; ``cpp/src/runtime_file.cpp`` reads it.

Reading never executes anything: the file is parsed as fixed binary records, every offset,
size, shape and checksum is checked, and a bad file raises :class:`ControllerFileError`
naming the file and what is wrong.
"""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path
from typing import Dict, List, Union

import numpy as np

from ..errors import InputError
from ..io import atomic_open

__all__ = ["MAGIC", "VERSION", "ControllerFileError", "write_sections", "read_sections", "DTYPES"]

MAGIC = b"MMRLCTRL"
VERSION = 1
#: Written as a little-endian uint32: the bytes 0D 0C 0B 0A on disk. A reader that sees
#: 0A 0B 0C 0D was handed a byte-swapped (big-endian) file.
ENDIAN_MARKER = 0x0A0B0C0D
HEADER_SIZE = 64
ENTRY_SIZE = 128
NAME_SIZE = 64
MAX_DIMS = 4
ALIGNMENT = 64
#: dtype code -> numpy dtype (little-endian). "text" is UTF-8 strings, each ended by a NUL byte.
DTYPES = {1: np.dtype("<f4"), 2: np.dtype("<i4"), 3: np.dtype("u1"), 4: "text", 5: np.dtype("<f8"), 6: np.dtype("<f2")}
_CODES = {np.dtype("<f4"): 1, np.dtype("<i4"): 2, np.dtype("u1"): 3, np.dtype("<f8"): 5, np.dtype("<f2"): 6}

_HEADER = struct.Struct("<8sIIIIQQII16x")          # magic, version, endian, header size, count, table offset,
                                                   # file size, table crc, header crc (of bytes 0..44)
_ENTRY = struct.Struct(f"<{NAME_SIZE}sII{MAX_DIMS}QQQI4x")  # name, dtype, ndim, shape, offset, size, crc
assert _HEADER.size == HEADER_SIZE and _ENTRY.size == ENTRY_SIZE

Section = Union[np.ndarray, List[str]]
PathLike = Union[str, "os.PathLike[str]"]


class ControllerFileError(InputError):
    """A controller file is truncated, corrupt, of another version or byte order, or not one at all."""


def _pad(n: int) -> int:
    return (-n) % ALIGNMENT


def _encode(name: str, value: Section):
    """(dtype code, shape, bytes) of one section."""
    if isinstance(value, (list, tuple)):
        texts = [str(v) for v in value]
        if any("\0" in t for t in texts):
            raise ValueError(f"section {name!r}: a string contains a NUL byte")
        return 4, (len(texts),), b"".join(t.encode("utf-8") + b"\0" for t in texts)
    arr = np.asarray(value)
    dtype = arr.dtype.newbyteorder("<") if arr.dtype.itemsize > 1 else arr.dtype
    if arr.dtype == np.bool_:
        dtype = np.dtype("u1")
    if dtype not in _CODES:
        raise ValueError(f"section {name!r}: unsupported dtype {arr.dtype} (float32, int32, uint8, float64, float16)")
    if arr.ndim > MAX_DIMS:
        raise ValueError(f"section {name!r}: {arr.ndim} dimensions, at most {MAX_DIMS}")
    return _CODES[dtype], arr.shape, np.ascontiguousarray(arr, dtype).tobytes()


def write_sections(path: PathLike, sections: Dict[str, Section]) -> int:
    """Write ``sections`` (name -> numeric array or list of strings) as a controller file,
    atomically (``mmrl.io.atomic_open``). Returns the file size in bytes."""
    encoded = []
    for name, value in sections.items():
        raw_name = name.encode("ascii")
        if not 0 < len(raw_name) < NAME_SIZE:
            raise ValueError(f"section name {name!r}: 1 to {NAME_SIZE - 1} ASCII characters")
        encoded.append((raw_name, *_encode(name, value)))
    table_size = len(encoded) * ENTRY_SIZE
    offset = HEADER_SIZE + table_size
    offset += _pad(offset)
    entries, payload = [], []
    for raw_name, code, shape, data in encoded:
        dims = list(shape) + [0] * (MAX_DIMS - len(shape))
        entries.append(_ENTRY.pack(raw_name, code, len(shape), *dims, offset, len(data), zlib.crc32(data)))
        payload.append(data + b"\0" * _pad(len(data)))
        offset += len(data) + _pad(len(data))
    table = b"".join(entries)
    head = _HEADER.pack(MAGIC, VERSION, ENDIAN_MARKER, HEADER_SIZE, len(encoded), HEADER_SIZE, offset,
                        zlib.crc32(table), 0)
    head = head[:44] + struct.pack("<I", zlib.crc32(head[:44])) + head[48:]
    with atomic_open(path, "wb") as f:
        f.write(head)
        f.write(table)
        f.write(b"\0" * _pad(HEADER_SIZE + len(table)))
        for chunk in payload:
            f.write(chunk)
    return offset


def _check_header(path: Path, data: bytes) -> tuple:
    def bad(what: str) -> ControllerFileError:
        return ControllerFileError(f"{path}: {what}")

    if len(data) < HEADER_SIZE:
        raise bad(f"truncated: {len(data)} bytes, shorter than the {HEADER_SIZE}-byte header")
    magic, version, endian, header_size, count, table_offset, file_size, table_crc, head_crc = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise bad("not an mmrl controller file (bad magic bytes)")
    if endian != ENDIAN_MARKER:
        if endian == struct.unpack("<I", struct.pack(">I", ENDIAN_MARKER))[0]:
            raise bad("big-endian (byte-swapped) file; controller files are little-endian")
        raise bad(f"bad endianness marker 0x{endian:08x}")
    if version != VERSION:
        raise bad(f"controller file version {version}, this mmrl reads version {VERSION}; export it again with "
                  "'mmrl export'")
    if zlib.crc32(data[:44]) != head_crc:
        raise bad("corrupt header (checksum mismatch)")
    if any(data[48:HEADER_SIZE]):
        raise bad("corrupt header (reserved bytes are not zero)")
    if header_size != HEADER_SIZE or table_offset != HEADER_SIZE:
        raise bad("corrupt header (sizes)")
    if file_size != len(data):
        raise bad(f"truncated or padded: the header says {file_size} bytes, the file has {len(data)}")
    if HEADER_SIZE + count * ENTRY_SIZE > len(data):
        raise bad(f"truncated: the section table ({count} entries) runs past the end of the file")
    table = data[HEADER_SIZE:HEADER_SIZE + count * ENTRY_SIZE]
    if zlib.crc32(table) != table_crc:
        raise bad("corrupt section table (checksum mismatch)")
    return count, table


def _decode(path: Path, data: bytes, entry: tuple) -> tuple:
    raw_name, code, ndim, *rest = entry
    dims, (offset, size, crc) = rest[:MAX_DIMS], rest[MAX_DIMS:]
    name = raw_name.rstrip(b"\0").decode("ascii", "replace")
    where = f"{path}: section '{name}'"
    if code not in DTYPES or ndim > MAX_DIMS:
        raise ControllerFileError(f"{where}: unknown dtype code {code} or {ndim} dimensions")
    if offset % ALIGNMENT or offset + size > len(data):
        raise ControllerFileError(f"{where}: bytes {offset}..{offset + size} lie outside the file or are misaligned")
    chunk = data[offset:offset + size]
    if zlib.crc32(chunk) != crc:
        raise ControllerFileError(f"{where}: corrupt (checksum mismatch)")
    shape = tuple(int(d) for d in dims[:ndim])
    if DTYPES[code] == "text":
        texts = chunk.split(b"\0")
        if not chunk.endswith(b"\0") or len(texts) - 1 != (shape[0] if shape else -1):
            raise ControllerFileError(f"{where}: expected {shape} NUL-ended strings")
        return name, [t.decode("utf-8") for t in texts[:-1]]
    dtype = DTYPES[code]
    if int(np.prod(shape, dtype=np.int64)) * dtype.itemsize != size:
        raise ControllerFileError(f"{where}: {size} bytes do not hold shape {shape} of {dtype}")
    return name, np.frombuffer(chunk, dtype).reshape(shape)


def read_sections(path: PathLike) -> Dict[str, Section]:
    """Read and check a controller file: name -> read-only array (or list of strings)."""
    path = Path(path)
    if not path.is_file():
        raise ControllerFileError(f"{path}: no such controller file")
    data = path.read_bytes()
    count, table = _check_header(path, data)
    out: Dict[str, Section] = {}
    for k in range(count):
        name, value = _decode(path, data, _ENTRY.unpack_from(table, k * ENTRY_SIZE))
        if name in out:
            raise ControllerFileError(f"{path}: section '{name}' appears twice")
        out[name] = value
    return out
