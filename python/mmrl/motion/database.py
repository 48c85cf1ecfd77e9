"""The motion database: clips, 27-d features, root motion, normalisation, save/load.

Offline: :meth:`Database.from_bvh` parses BVH files (in C++, in parallel: Y up, resampled
to the database's rate) and builds the features. Runtime: :meth:`Database.match` searches
the normalized features. A Database never changes after it is built: matchers and envs
borrow its rows; :meth:`Database.with_weights` returns a new one.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _core
from .bvh import _options as _bvh_options, check_motion, warn_if_implausible
from .checks import check_usable, is_bvh_file, is_database_file
from ..errors import InputError
from ..arrays import MAX_ENTRIES, index_array, real_array
from ..io import atomic_write_npz

PathLike = Union[str, os.PathLike]

FEATURE_DIM: int = _core.FEATURE_DIM
POSE_DIM: int = _core.POSE_DIM
TRAJECTORY_DIM: int = _core.TRAJECTORY_DIM
#: (name, columns, default weight) of each normalisation block.
FEATURE_BLOCKS: List[Tuple[str, List[int], float]] = [tuple(b) for b in _core.FEATURE_BLOCKS]
BLOCK_NAMES: List[str] = [b[0] for b in FEATURE_BLOCKS]
DEFAULT_WEIGHTS: Dict[str, float] = {b[0]: b[2] for b in FEATURE_BLOCKS}

FILE_FORMAT = "mmrl.database"  # the file format's name, not a module path: never changes with the layout
# Version 2 files written before import metadata existed lack "clip_source_fps" and
# "clip_source_up"; they load with the database's rate and Y up.
FILE_VERSION = 2
#: The database's frame rate unless told otherwise: the trajectory offsets (+10/+20/+30
#: frames) and the decision interval (6 frames) mean 1/3, 2/3, 1 s and 0.2 s at this rate.
DEFAULT_FPS = 30.0


class DatabaseFileError(ValueError):
    """A database file is corrupt, foreign or of an unsupported version."""


def find_bvh_files(paths: Union[PathLike, Iterable[PathLike]]) -> List[Path]:
    """Expand a file, a directory (searched recursively, sorted, hidden files skipped) or a list of them."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    out: List[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            # Hidden files are skipped: a torn temp file of an interrupted download
            # (mmrl.io's ".<name>.<random>.tmp") or a macOS "._" resource fork is no clip.
            found = sorted(q for q in p.rglob("*") if q.suffix.lower() == ".bvh" and not q.name.startswith(".")
                           and q.is_file())
            if not found:
                raise FileNotFoundError(f"{p}: no .bvh files in this directory")
            out.extend(found)
        elif p.is_file():
            if is_database_file(p):
                raise InputError(f"{p}: a database file, not BVH; pass it with --db {p}")
            out.append(p)
        else:
            raise FileNotFoundError(f"{p}: no such file or directory")
    if not out:
        raise ValueError("no BVH files given")
    return out


def _weights_list(weights: Optional[Union[Mapping[str, float], Sequence[float]]], base: Sequence[float]) -> List[float]:
    if weights is None:
        return list(base)
    if isinstance(weights, Mapping):
        unknown = set(weights) - set(BLOCK_NAMES)
        if unknown:
            raise ValueError(f"weights: unknown feature blocks {sorted(unknown)}; blocks are {BLOCK_NAMES}")
        w = list(base)
        for k, v in weights.items():
            w[BLOCK_NAMES.index(k)] = float(v)
        return w
    w = [float(v) for v in weights]
    if len(w) != len(BLOCK_NAMES):
        raise ValueError(f"weights: expected {len(BLOCK_NAMES)} values ({BLOCK_NAMES}), got {len(w)}")
    return w


class Database:
    """A motion-matching database over one skeleton.

    Arrays (read-only numpy views of C++ memory, N frames, J joints, C clips):

    - ``features`` (N, 27) raw units; ``normalized_features`` (N, 27) searched by ``match``;
    - ``clip_ranges`` (C, 2) start inclusive, stop exclusive, in input order (mirrored
      copies, if any, follow all originals in the same order);
    - ``valid_mask`` (N,) bool: frames whose +30 future stays inside their clip;
    - ``root_positions`` (N, 3) and ``root_yaws`` (N,): the character frame in world space;
    - ``root_deltas`` (N, 3): (dx, dz, dyaw) from frame i to i+1 in frame i's character frame;
    - ``bone_translations`` (N, J, 3), ``bone_rotations`` (N, J, 4) local pose (w, x, y, z);
    - ``contacts`` (N, 2) bool: left/right foot planted (toe or ankle near the ground and
      slower than 0.15 m/s horizontally, median-filtered over 5 frames);
    - ``clip_source_fps`` (C,) the files' frame rates before resampling to ``fps``;
      ``clip_source_up`` (C,) their up axes, ``"y"`` or ``"z"`` (rotated to Y up).

    Immutable: every array is read-only, and matchers (``matcher``, envs, controllers)
    keep borrowing the rows they were built on. :meth:`with_weights` returns a new Database.
    """

    def __init__(self, core: "_core.Database", clip_source_fps: Optional[Sequence[float]] = None,
                 clip_source_up: Optional[Sequence[str]] = None):
        self._db = core
        self._matcher = None
        c = core.num_clips
        fps = np.full(c, core.fps, np.float32) if clip_source_fps is None else np.asarray(clip_source_fps, np.float32)
        up = np.full(c, "y") if clip_source_up is None else np.asarray(clip_source_up, np.str_)
        if fps.shape != (c,) or up.shape != (c,) or not set(up.tolist()) <= {"y", "z"}:
            raise ValueError(f"clip_source_fps and clip_source_up: expected {c} entries each ('y' or 'z' for up)")
        fps.setflags(write=False)
        up.setflags(write=False)
        self._clip_source_fps, self._clip_source_up = fps, up

    # ----------------------------------------------------------------- building
    @classmethod
    def from_bvh(
        cls,
        paths: Union[PathLike, Iterable[PathLike]],
        *,
        mirror: bool = False,
        scale: Optional[float] = None,
        up: Optional[str] = None,
        fps: Optional[float] = DEFAULT_FPS,
        roles: Optional[Mapping[str, str]] = None,
        weights: Optional[Union[Mapping[str, float], Sequence[float]]] = None,
        progress: bool = False,
        num_workers: Optional[int] = None,
        tags: "Optional[TagRules]" = None,
    ) -> "Database":
        """Build a database from BVH files.

        Args:
            paths: a file, a directory (searched recursively, in sorted order) or a list.
            mirror: add a left/right mirrored copy of every clip.
            scale: file units to meters; ``None`` infers it per file (see :func:`mmrl.load_bvh`).
            up: the files' up axis, ``"y"`` or ``"z"``; ``None`` detects it per file.
            fps: the database's frame rate; clips at other rates are resampled on import
                (translations linear, rotations slerp). ``None`` keeps the files' rate
                (they must then agree).
            roles: overrides of the joint-role detection, e.g. ``{"left_foot": "LeftAnkle"}``.
            weights: block weights by name (see ``BLOCK_NAMES``) or as a 5-sequence.
            progress: show a progress bar while parsing.
            num_workers: parsing threads (default: all cores).
            tags: where the clips' tags come from (:class:`mmrl.motion.tags.TagRules`; default:
                the automatic rules only, the known datasets' naming and an ``mmrl_tags.csv``
                sidecar at the top of a folder).

        Warns:
            MotionImportWarning: per file whose motion looks implausible after import
                (lying flat, travelling vertically; see :func:`mmrl.motion.bvh.check_motion`).
        """
        files = find_bvh_files(paths)
        s, u, f = _bvh_options(scale, up, fps)
        workers = num_workers or os.cpu_count() or 1
        from tqdm import tqdm

        # disable None: a bar only on a terminal
        bar = tqdm(total=len(files), unit="file", desc="parsing BVH", disable=None if progress else True)

        def load(path):  # runs in a worker thread; the C++ releases the GIL
            motion = _core.bvh_load(os.fspath(path), s, u, f)
            return motion, check_motion(motion)

        motions = []
        try:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                for m, problems in pool.map(load, files):
                    warn_if_implausible(m, problems, stacklevel=2)  # from this thread, in file order
                    motions.append(m)
                    bar.update(1)
        finally:
            bar.close()
        from .tags import TagRules, clip_tags_for_files

        roots = [Path(p) for p in ([paths] if isinstance(paths, (str, os.PathLike)) else list(paths))]
        clip_tags = clip_tags_for_files(files, roots, tags if tags is not None else TagRules())
        return cls.from_motions(motions, mirror=mirror, roles=roles, weights=weights, fps=fps, clip_tags=clip_tags)

    @classmethod
    def from_motions(cls, motions: Sequence["_core.Motion"], *, mirror: bool = False,
                     roles: Optional[Mapping[str, str]] = None,
                     weights: Optional[Union[Mapping[str, float], Sequence[float]]] = None,
                     fps: Optional[float] = DEFAULT_FPS,
                     clip_tags: Optional[Tuple[Sequence[str], np.ndarray]] = None) -> "Database":
        """Build a database from parsed motions (see :func:`mmrl.load_bvh`); motions at
        another rate than ``fps`` are resampled (``None`` keeps their rate). ``clip_tags``:
        ``(tag names, (len(motions), T) 0/1 matrix)``, the tags of each motion (a mirrored copy
        gets its original's)."""
        if fps is not None and not (0 < fps < float("inf")):
            raise ValueError(f"fps must be positive, got {fps!r}")
        motions = list(motions)
        if fps is not None:
            motions = [m.resampled(fps) if abs(m.fps - fps) > 1e-4 * fps else m for m in motions]
        w = _weights_list(weights, [DEFAULT_WEIGHTS[n] for n in BLOCK_NAMES])
        try:
            core = _core.Database.build(motions, bool(mirror), dict(roles or {}), w)
        except _core.JointRoleError:
            raise
        except ValueError as e:  # the data's: two skeletons, no clip, a bad weight
            raise InputError(str(e)) from None
        check_usable(core, motions)
        if clip_tags is not None and len(clip_tags[0]):
            names, matrix = list(clip_tags[0]), np.asarray(clip_tags[1])
            if matrix.shape != (len(motions), len(names)):
                raise ValueError(f"clip_tags: expected a ({len(motions)}, {len(names)}) matrix, got {matrix.shape}")
            matrix = np.ascontiguousarray(np.vstack([matrix, matrix]) if mirror else matrix, np.uint8)
            core.set_tags(names, matrix)
        src_fps = [m.source_fps for m in motions] * (2 if mirror else 1)
        src_up = [m.up_axis for m in motions] * (2 if mirror else 1)
        return cls(core, src_fps, src_up)

    # ----------------------------------------------------------------- properties
    @property
    def source_scale(self) -> float:
        """The file units -> meters of the source BVH (as given or inferred)."""
        return float(self._db.source_scale)

    num_frames = property(lambda self: self._db.num_frames, doc="Number of frames N.")
    num_joints = property(lambda self: self._db.num_joints, doc="Number of joints J.")
    num_clips = property(lambda self: self._db.num_clips, doc="Number of clips C.")
    fps = property(lambda self: self._db.fps, doc="Frames per second.")
    joint_names = property(lambda self: list(self._db.joint_names))
    parents = property(lambda self: list(self._db.parents))
    roles = property(lambda self: dict(self._db.roles), doc="Role name -> joint name.")
    clip_names = property(lambda self: list(self._db.clip_names))
    tag_names = property(lambda self: list(self._db.tag_names),
                         doc="The tags clips carry, ``group=value`` (mmrl.motion.tags); [] when untagged.")
    clip_tags = property(lambda self: self._db.clip_tags.view(np.bool_),
                         doc="(C, T) bool: clip c carries tag t.")
    features = property(lambda self: self._db.features)
    normalized_features = property(lambda self: self._db.normalized_features)
    valid_mask = property(lambda self: self._db.valid_mask.view(np.bool_))
    frame_clip = property(lambda self: self._db.frame_clip, doc="Clip index of each frame.")
    contacts = property(lambda self: self._db.contacts.view(np.bool_), doc="(N, 2) left/right foot contacts.")
    path_samples = property(lambda self: self._db.path_samples,
                            doc="(N, 9, 2) root (x, z) that playing from each valid frame reaches "
                                "``_core.PATH_SAMPLE_FRAMES`` frames later, in that frame's character frame "
                                "(zeros for frames that cannot be matched); the collision-aware search's paths.")
    feature_mean = property(lambda self: self._state()["feature_mean"])
    feature_scale = property(lambda self: self._db.feature_scale,
                             doc="Per-column divisor: normalized = (features - mean) / scale.")

    def _state(self):
        return self._db.state()

    clip_ranges = property(lambda self: self._state()["clip_ranges"])
    clip_mirrored = property(lambda self: self._state()["clip_mirrored"].view(np.bool_))
    root_positions = property(lambda self: self._state()["root_positions"])
    root_yaws = property(lambda self: self._state()["root_yaws"])
    root_deltas = property(lambda self: self._state()["root_deltas"])
    bone_translations = property(lambda self: self._state()["bone_translations"])
    bone_rotations = property(lambda self: self._state()["bone_rotations"])

    @property
    def weights(self) -> Dict[str, float]:
        w = self._state()["weights"]
        return {n: float(w[i]) for i, n in enumerate(BLOCK_NAMES)}

    def with_weights(self, weights: Union[Mapping[str, float], Sequence[float]]) -> "Database":
        """A new Database with other block weights (by name, the others kept, or as a
        5-sequence): the same features, mean and block scales, renormalized rows. This one,
        and every matcher or env built on it, stays unchanged."""
        cur = self._state()["weights"].tolist()
        return Database(self._db.with_weights(_weights_list(weights, cur)), self._clip_source_fps,
                        self._clip_source_up)

    clip_source_fps = property(lambda self: self._clip_source_fps,
                               doc="(C,) float32: each clip's frame rate in its file, before resampling to ``fps``.")
    clip_source_up = property(lambda self: self._clip_source_up,
                              doc="(C,) str: each clip's up axis in its file, ``\"y\"`` or ``\"z\"`` (rotated to Y up).")

    def normalize(self, features: np.ndarray) -> np.ndarray:
        """Map raw features (..., 27) into the normalized, weighted search space (float32;
        NaN stays NaN)."""
        f = real_array(features, "features", (..., FEATURE_DIM))
        return ((f - self.feature_mean) / self.feature_scale).astype(np.float32)

    def denormalize(self, normalized: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normalize`."""
        n = real_array(normalized, "normalized", (..., FEATURE_DIM))
        return (n * self.feature_scale + self.feature_mean).astype(np.float32)

    @property
    def minutes(self) -> float:
        return self.num_frames / self.fps / 60.0

    def __repr__(self) -> str:
        return (f"<mmrl.Database: {self.num_clips} clips, {self.num_frames} frames "
                f"({self.minutes:.1f} min) at {self.fps:g} fps, {self.num_joints} joints>")

    # ----------------------------------------------------------------- save / load
    def save(self, path: PathLike) -> None:
        """Write the database to one versioned ``.npz`` file, atomically."""
        path = Path(path)
        s = self._state()
        arrays = {k: np.asarray(v) for k, v in s.items()
                  if k not in ("joint_names", "channels", "clip_names", "tag_names", "roles", "fps", "source_scale")}
        for k in ("tag_names", "joint_names", "channels", "clip_names"):
            arrays[k] = np.array(s[k], dtype=np.str_).reshape(-1)
        arrays["roles"] = np.array(s["roles"], dtype=np.int32)
        arrays["fps"] = np.array(s["fps"], dtype=np.float32)
        arrays["source_scale"] = np.array(s["source_scale"], dtype=np.float32)
        arrays["clip_source_fps"] = self._clip_source_fps
        arrays["clip_source_up"] = self._clip_source_up
        arrays["format"] = np.array(FILE_FORMAT)
        arrays["version"] = np.array(FILE_VERSION, dtype=np.int32)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_npz(path, **arrays)

    @classmethod
    def load(cls, path: PathLike) -> "Database":
        """Load a database written by :meth:`save`.

        Raises:
            DatabaseFileError: the file is corrupt, not an mmrl database, or of another version.
        """
        path = Path(path)
        if path.is_dir():
            raise DatabaseFileError(f"{path}: a folder, not a database file; to use the BVH files in it pass "
                                    f"--data {path}, or build a database first: mmrl db build {path} -o db.npz")
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such database file")
        if is_bvh_file(path):
            raise DatabaseFileError(f"{path}: a BVH file, not a database; pass it with --data {path}, or build a "
                                    f"database first: mmrl db build {path} -o db.npz")
        try:
            with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
                if "format" not in z.files or str(z["format"]) != FILE_FORMAT:
                    raise DatabaseFileError(f"{path}: not an mmrl database file")
                version = int(z["version"])
                if version != FILE_VERSION:
                    raise DatabaseFileError(f"{path}: database file version {version}, this mmrl reads version {FILE_VERSION}; rebuild it with 'mmrl db build'")
                state = {k: z[k] for k in z.files if k not in ("format", "version")}
            source_fps = state.pop("clip_source_fps", None)
            source_up = state.pop("clip_source_up", None)
        except DatabaseFileError:
            raise
        except Exception as e:  # zipfile, zlib and numpy's header parser raise many types
            # (tokenize.TokenError from a mangled .npy header: tests/fuzz/fuzz_python.py found it)
            if isinstance(e, ValueError) and "allow_pickle" in str(e):
                raise DatabaseFileError(f"{path}: refused: it holds pickled Python objects (an object array); "
                                        f"mmrl never unpickles them, since loading them could run code") from None
            raise DatabaseFileError(f"{path}: corrupt or unreadable database file ({e})") from e
        try:
            state["joint_names"] = [str(x) for x in state["joint_names"]]
            state["channels"] = [str(x) for x in state["channels"]]
            state["clip_names"] = [str(x) for x in state["clip_names"]]
            if "tag_names" in state:
                state["tag_names"] = [str(x) for x in np.asarray(state["tag_names"]).reshape(-1)]
            state["roles"] = [int(x) for x in state["roles"]]
            state["fps"] = float(state["fps"])
            state["source_scale"] = float(state["source_scale"])
            state = {k: (np.ascontiguousarray(v) if isinstance(v, np.ndarray) else v) for k, v in state.items()}
            return cls(_core.Database.from_state(state), source_fps, source_up)
        except Exception as e:  # any malformed entry (OverflowError from a huge role index, ...)
            raise DatabaseFileError(f"{path}: corrupt database file ({e})") from e

    # ----------------------------------------------------------------- sharing between processes
    def shared_arrays(self) -> Dict[str, Any]:
        """Everything :meth:`from_shared_arrays` needs, as numpy arrays and plain lists: what
        ``ray.put`` stores once in Ray's shared-memory object store (mmrl.integrations.rllib).
        The arrays are views of this database's memory (nothing is copied here)."""
        state = dict(self._db.state())
        state["normalized"] = self.normalized_features
        state["clip_source_fps"] = self._clip_source_fps
        state["clip_source_up"] = self._clip_source_up
        return state

    @classmethod
    def from_shared_arrays(cls, arrays: Mapping[str, Any]) -> "Database":
        """A database over ``arrays`` (from :meth:`shared_arrays`) that borrows its large
        per-frame arrays instead of copying them: features, normalized features, local poses
        and root tracks stay wherever the arrays live (read-only memory is fine, e.g. what
        ``ray.get`` returns from the object store). ``borrowed_arrays`` lists them. The small
        arrays (clips, contacts, skeleton) are copied. Every array is checked as on load."""
        state = dict(arrays)
        fps, up = state.pop("clip_source_fps", None), state.pop("clip_source_up", None)
        return cls(_core.Database.from_state(state, borrow=True), fps, up)

    @property
    def borrowed_arrays(self) -> List[str]:
        """The per-frame arrays this database borrows (see :meth:`from_shared_arrays`)."""
        return list(self._db.borrowed_arrays)

    # ----------------------------------------------------------------- matching
    def match(self, queries: np.ndarray, *, normalized: bool = False,
              bound_indices: Optional[np.ndarray] = None,
              exclude: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
        """Nearest valid frame for each query.

        Args:
            queries: (M, 27) float32 raw features, or already normalized if ``normalized``.
            bound_indices: optional (M,) int64 current frames; a query keeps its bound frame
                unless another valid frame is strictly better.
            exclude: optional (M, 2) int64 row windows [lo, hi) a query may not return (the
                bound frame itself stays allowed). See :meth:`controller_windows`.

        Returns:
            (indices (M,) int64, costs (M,) float32): costs are squared distances in the
            normalized, weighted space.
        """
        q = queries
        if not isinstance(q, np.ndarray):
            raise TypeError(f"queries: expected a numpy array, got {type(q).__name__}")
        if q.dtype != np.float32:
            raise TypeError(f"queries: expected dtype float32, got {q.dtype}")
        if q.ndim != 2 or q.shape[1] != FEATURE_DIM:
            raise ValueError(f"queries: expected shape (M, {FEATURE_DIM}), got {q.shape}")
        if q.size > MAX_ENTRIES:  # e.g. a broadcast view of 2**31 rows: refused before any copy
            raise ValueError(f"queries: {q.size} entries (shape {q.shape}) is over the limit of {MAX_ENTRIES}")
        if not np.isfinite(q).all():
            raise ValueError("queries: contains NaN or inf")
        if not normalized:
            q = self.normalize(q)
        return self.matcher.match(np.ascontiguousarray(q), bound_indices, exclude)

    def controller_windows(self, frames: np.ndarray, radius: int = _core.MATCH_EXCLUDE_WINDOW) -> np.ndarray:
        """The rows a controller at ``frames`` skips: ``radius`` frames either side, within
        each frame's clip ((M, 2) int64 [lo, hi)), as in the runtime's match rule."""
        frames = index_array(frames, "frames", (None,), high=self.num_frames, what="the database's frames")
        if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
            raise ValueError(f"radius: expected an int >= 0, got {radius!r}")
        ranges = self.clip_ranges[self.frame_clip[frames]]
        lo = np.maximum(ranges[:, 0], frames - radius)
        hi = np.minimum(ranges[:, 1], frames + radius + 1)
        return np.ascontiguousarray(np.stack([lo, hi], 1).astype(np.int64))

    @property
    def matcher(self):
        """The search structure over the normalized features (built on first use)."""
        if self._matcher is None:
            self._matcher = _core.Matcher(self.normalized_features, self._db.valid_mask)
        return self._matcher
