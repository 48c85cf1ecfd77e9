"""Write the seed corpora of the fuzz targets (docs/hardening.md) into tests/fuzz/corpus/<target>/.

    PYTHONPATH=python python tests/fuzz/make_corpus.py

The seeds are small real files (a hand-written BVH, short synthetic clips, a database of two
short synthetic clips, a controller exported from it) and the malformed cases of the unit
tests (tests/test_bvh.py, tests/test_database.py, tests/test_runtime_file.py). The output is
checked in; run this again only when a file format changes. Deterministic: the same files
every time.

Targets and their input encodings:
  bvh           one options byte (cpp/fuzz/fuzz_bvh.cpp), then BVH text
  database      the arrays of a database in the plain encoding of cpp/fuzz/fuzz_database.cpp
  runtime_file  an exported controller file (.mmrl)
  checkpoint    a PPO checkpoint (torch.save zip), for tests/fuzz/fuzz_python.py
  database_npz  a database file (.npz), for tests/fuzz/fuzz_python.py
"""
from __future__ import annotations

import io
import struct
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the unit tests' modules, for their malformed cases

from test_bvh import GOOD as GOOD_BVH  # noqa: E402  (the unit tests' valid file)

# The malformed cases of tests/test_bvh.py, as edits of GOOD_BVH.
BAD_BVH = {
    "truncated": GOOD_BVH.replace("Frames: 2", "Frames: 3"),
    "value_count": GOOD_BVH.replace("10 95 0 0 90 0 0 0 0", "10 95 0 0 90 0 0 0"),
    "unknown_channel": GOOD_BVH.replace("Zrotation Xrotation Yrotation\n\t\tEnd", "Zrotation Wrotation Yrotation\n\t\tEnd"),
    "nan": GOOD_BVH.replace("10 95 0 0 90", "10 95 nan 0 90"),
    "huge_value": GOOD_BVH.replace("10 95 0 0 90", "10 95 1e99 0 90"),
    "zero_frames": GOOD_BVH.replace("Frames: 2", "Frames: 0"),
    "missing_motion": GOOD_BVH.split("MOTION")[0],
    "unbalanced": GOOD_BVH.replace("\t}\n}\nMOTION", "\t}\nMOTION"),
    "duplicate_joint": GOOD_BVH.replace("JOINT Spine", "JOINT Hips"),
    "binary": "HIERARCHY\x00\x01\x02 binary",
}
# Its valid variants (tests/test_bvh.py).
VARIANT_BVH = {
    "crlf": GOOD_BVH.replace("\n", "\r\n"),
    "three_channel_root": GOOD_BVH.replace(
        "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation", "CHANNELS 3 Yrotation Xrotation Zrotation"
    ).replace("0 95 0 0 0 0 0 0 0", "0 0 0 0 0 0").replace("10 95 0 0 90 0 0 0 0", "0 90 0 0 0 0"),
}


def write(target: str, name: str, data: bytes) -> None:
    out = HERE / "corpus" / target
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_bytes(data)


def bvh_seeds(tmp: Path) -> None:
    from mmrl import synth

    write("bvh", "good", b"\x00" + GOOD_BVH.encode())
    # The same file through the other import paths (options byte, cpp/fuzz/fuzz_bvh.cpp):
    # Z up; scale 0.01 and resampled to 24 fps.
    write("bvh", "good_z_up", b"\x02" + GOOD_BVH.encode())
    write("bvh", "good_scaled_24fps", bytes([4 | (1 << 3)]) + GOOD_BVH.encode())
    for name, text in BAD_BVH.items():
        write("bvh", f"bad_{name}", b"\x00" + text.encode("latin-1"))
    for name, text in VARIANT_BVH.items():
        write("bvh", f"good_{name}", b"\x00" + text.encode())
    # Synthetic clips on the full synth skeleton, a few frames each (walking, turning).
    for name, kw in {"walk": dict(speed=1.4), "turn": dict(speed=0.8, turn_rate=1.0)}.items():
        path = tmp / f"{name}.bvh"
        synth.write_clip(path, seconds=1.0, fps=10, **kw)
        write("bvh", f"synth_{name}", b"\x00" + path.read_bytes())


def tiny_database(tmp: Path):
    """Two synthetic clips of one second: 60 frames of the synth skeleton."""
    import mmrl
    from mmrl import synth

    clips = tmp / "clips"
    clips.mkdir()
    synth.write_clip(clips / "walk.bvh", speed=1.4, seconds=1.0, fps=30)
    synth.write_clip(clips / "turn.bvh", speed=0.8, turn_rate=1.0, seconds=1.0, fps=30, seed=1)
    return mmrl.Database.from_bvh(clips)


def encode_state(state: dict) -> bytes:
    """The plain encoding of cpp/fuzz/fuzz_database.cpp."""
    out = io.BytesIO()

    def texts(values):
        out.write(struct.pack("<H", len(values)))
        for v in values:
            b = str(v).encode()
            out.write(struct.pack("<H", len(b)) + b)

    def array(values, dtype):
        a = np.ascontiguousarray(np.asarray(values, dtype))
        out.write(struct.pack("<B", a.ndim) + struct.pack(f"<{a.ndim}I", *a.shape) + a.tobytes())

    texts(state["joint_names"])
    array(state["parents"], "<i4")
    array(state["offsets"], "<f4")
    array(state["end_sites"], "<f4")
    array(state["has_end_site"], "u1")
    texts(state["channels"])
    array(state["roles"], "<i4")
    out.write(struct.pack("<ff", state["fps"], state["source_scale"]))
    texts(state["clip_names"])
    array(state["clip_ranges"], "<i4")
    array(state["clip_mirrored"], "u1")
    for key in ("bone_translations", "bone_rotations", "root_positions", "root_yaws", "root_deltas", "features"):
        array(state[key], "<f4")
    array(state["contacts"], "u1")
    for key in ("feature_mean", "block_scale", "weights"):
        array(state[key], "<f4")
    return out.getvalue()


def database_seeds(db) -> None:
    state = {k: (list(v) if isinstance(v, list) else v) for k, v in db._state().items()}
    write("database", "tiny", encode_state(state))
    # The first clip cut to 25 frames (it keeps a few valid frames).
    first = dict(state)
    n = 25
    first["clip_names"] = state["clip_names"][:1]
    first["clip_ranges"] = np.array([[0, n]], np.int32)
    first["clip_mirrored"] = np.asarray(state["clip_mirrored"])[:1]
    for key in ("bone_translations", "bone_rotations", "root_positions", "root_yaws", "root_deltas", "features",
                "contacts"):
        first[key] = np.asarray(state[key])[:n]
    write("database", "one_clip", encode_state(first))
    # The malformed cases of tests/test_database.py and test_runtime_file.py, as arrays.
    bad = dict(first, features=np.asarray(first["features"])[:-5])
    write("database", "bad_short_features", encode_state(bad))
    bad = dict(first, root_yaws=np.zeros(3, np.float32))
    write("database", "bad_root_yaws_shape", encode_state(bad))
    feats = np.array(first["features"], np.float32)
    feats[3, 4] = np.nan
    write("database", "bad_nan_feature", encode_state(dict(first, features=feats)))
    write("database", "bad_roles", encode_state(dict(first, roles=[0] * 8)))


def runtime_seeds(db, tmp: Path) -> None:
    import torch

    from mmrl.rl.networks import PlaneActorCritic
    from mmrl.export.runtime_export import controller_sections, write_controller
    from mmrl.export.runtime_file import write_sections
    from mmrl.tasks.plane import PlaneConfig
    from mmrl.rl.trained_policy import ObsNormalizer, Policy

    torch.manual_seed(0)
    model = PlaneActorCritic(17, 12, hidden=(8,))
    norm = ObsNormalizer(17, True, None, 10.0, torch.device("cpu"))
    policy = Policy(model, norm, torch.device("cpu"))
    path = tmp / "tiny.mmrl"
    write_controller(path, db, policy, "plane", PlaneConfig())
    good = path.read_bytes()
    write("runtime_file", "tiny_plane", good)
    # The malformed cases of tests/test_runtime_file.py.
    write("runtime_file", "bad_truncated", good[: len(good) // 2])
    write("runtime_file", "bad_version", good[:8] + struct.pack("<I", 99) + good[12:])
    sections = controller_sections(db, policy, "plane", PlaneConfig())
    cases = {
        "missing": {k: v for k, v in sections.items() if k != "policy.header"},
        "shape": dict(sections, **{"db.root_yaws": np.zeros(3, np.float32)}),
        "dtype": dict(sections, **{"db.parents": np.zeros(db.num_joints, np.float32)}),
        "valid": dict(sections, **{"db.valid": np.zeros(db.num_frames, np.uint8)}),
        "task": dict(sections, **{"task.keys": ["a"], "task.values": np.zeros(1)}),
    }
    for name, secs in cases.items():
        write_sections(tmp / f"{name}.mmrl", secs)
        write("runtime_file", f"bad_{name}", (tmp / f"{name}.mmrl").read_bytes())


def python_seeds(db, tmp: Path) -> None:
    import torch

    from mmrl.rl.checkpoints import save_checkpoint
    from mmrl.rl.networks import PlaneActorCritic
    from mmrl.rl.trained_policy import ObsNormalizer

    db.save(tmp / "db.npz")
    write("database_npz", "tiny", (tmp / "db.npz").read_bytes())
    write("database_npz", "bad_not_zip", b"not a zip file at all")
    torch.manual_seed(0)
    model = PlaneActorCritic(17, 12, hidden=(4,))
    norm = ObsNormalizer(17, True, None, 10.0, torch.device("cpu"))
    state = {"model": model.state_dict(), "model_class": "PlaneActorCritic", "model_kwargs": model.init_kwargs,
             "obs_normalizer": norm.state_dict(), "global_step": 10, "iteration": 1,
             "action_center": None, "action_half": None}
    save_checkpoint(state, tmp / "ckpt.pt")
    raw = (tmp / "ckpt.pt").read_bytes()
    write("checkpoint", "tiny", raw)
    write("checkpoint", "bad_truncated", raw[: len(raw) // 2])


def main() -> int:
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        bvh_seeds(tmp)
        db = tiny_database(tmp)
        database_seeds(db)
        runtime_seeds(db, tmp)
        python_seeds(db, tmp)
    for target in sorted((HERE / "corpus").iterdir()):
        files = list(target.iterdir())
        print(f"{target.name}: {len(files)} seeds, {sum(f.stat().st_size for f in files)} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
