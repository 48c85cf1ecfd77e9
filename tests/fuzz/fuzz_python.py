"""atheris fuzz targets for the loaders written in Python (docs/hardening.md).

    python tests/fuzz/fuzz_python.py TARGET [libFuzzer flags] [corpus dirs]
    TARGET: checkpoint    a PPO checkpoint file -> mmrl.rl.trained_policy.load_policy
                          (torch.load(weights_only=True), the format checks, the registered
                          network rebuilt and its weights loaded, the observation normalizer)
            database_npz  a database file -> mmrl.Database.load (numpy's .npz reader with
                          allow_pickle=False, the Python checks, then the C++ database_from_state)

tools/fuzz.sh runs them like the C++ targets. A bad file must raise the loader's own error
(CheckpointError, DatabaseFileError); any other exception, a crash or a hang is a finding.

What is instrumented: atheris guides the search by the coverage of the Python code of mmrl's
loaders, of torch's serialization and weights-only unpickler, and of numpy's .npy/.npz readers
and zipfile. torch's zip reader (C++, miniz) and numpy's C parts run uninstrumented: a crash
in them is still caught (the process dies and atheris writes the input), but the search is
not guided inside them. The C++ database rules are fuzzed with coverage by cpp/fuzz/fuzz_database.cpp.
"""
from __future__ import annotations

import os
import sys
import tempfile
import types

import warnings

import atheris

with atheris.instrument_imports(include=["mmrl"]):
    import mmrl  # noqa: F401  (instrumented: its Python loaders)
    from mmrl.rl.checkpoints import CheckpointError
    from mmrl.motion.database import Database, DatabaseFileError
    from mmrl.rl.trained_policy import load_policy

import numpy.lib.format
import torch._weights_only_unpickler
import torch.serialization
import zipfile

# torch warns about odd pickle protocols in mutated files; the warnings are noise here.
warnings.simplefilter("ignore")

# One scratch file in memory (the loaders take paths).
SCRATCH = os.path.join("/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir(), f"mmrl-fuzz-{os.getpid()}")


def instrument_module(module: types.ModuleType) -> None:
    """Coverage for the functions and methods defined in a module already imported."""
    for value in list(vars(module).values()):
        if isinstance(value, types.FunctionType) and value.__module__ == module.__name__:
            atheris.instrument_func(value)
        elif isinstance(value, type) and value.__module__ == module.__name__:
            for attr in vars(value).values():
                if isinstance(attr, types.FunctionType):
                    atheris.instrument_func(attr)


for _module in (torch.serialization, torch._weights_only_unpickler, numpy.lib.format, zipfile):
    instrument_module(_module)
try:  # numpy >= 2: the npz reader lives here
    import numpy.lib._npyio_impl as _npyio

    instrument_module(_npyio)
except ImportError:
    pass


# zipfile checks each member's CRC-32 as it reads, so almost every mutation of an .npz would
# stop there: the fuzzer skips that check (as fuzzing builds of C libraries skip checksums),
# and the harness of runtime_file rewrites its checksums for the same reason. A real corrupt
# file still fails the check; tests/test_database.py covers that. torch's checkpoint reader
# checks no CRC.
zipfile.ZipExtFile._update_crc = lambda self, newdata: None


def write_scratch(data: bytes) -> str:
    with open(SCRATCH, "wb") as f:
        f.write(data)
    return SCRATCH


def checkpoint(data: bytes) -> None:
    try:
        load_policy(write_scratch(data))
    except CheckpointError:
        pass


def database_npz(data: bytes) -> None:
    try:
        Database.load(write_scratch(data))
    except DatabaseFileError:
        pass


TARGETS = {"checkpoint": checkpoint, "database_npz": database_npz}


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in TARGETS:
        sys.exit(f"usage: {sys.argv[0]} {{{','.join(TARGETS)}}} [libFuzzer flags] [corpus dirs]")
    target = TARGETS[sys.argv.pop(1)]
    try:
        atheris.Setup(sys.argv, target)
        atheris.Fuzz()
    finally:
        if os.path.exists(SCRATCH):
            os.unlink(SCRATCH)


if __name__ == "__main__":
    main()
