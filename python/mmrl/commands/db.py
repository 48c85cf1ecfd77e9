"""``mmrl db build`` and ``mmrl db info``."""
from __future__ import annotations

import argparse
import time

import numpy as np

from .. import _core

from ..motion.database import DEFAULT_FPS
from ..errors import InputError
from ..motion.kinds import kinds_line
from ..motion.sources import load_any
from .common import read_number, deprecated_alias, output_path, positive_float, warn


def parse_roles(items):
    roles = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--role expects ROLE=JOINT, got {item!r}")
        k, v = item.split("=", 1)
        roles[k.strip()] = v.strip()
    return roles


def register_cli(sub) -> None:
    db = sub.add_parser("db", help="build and inspect motion databases")
    dsub = db.add_subparsers(dest="db_command", metavar="SUBCOMMAND")
    dsub.required = True

    b = dsub.add_parser("build", help="build a database from BVH files or directories")
    b.add_argument("data", nargs="+", help="BVH files or folders (searched recursively)")
    b.add_argument("-o", "--output", required=True, help="output database file (.npz; its folder is created)")
    b.add_argument("--mirror", action="store_true", help="add left/right mirrored copies of every clip")
    b.add_argument("--scale", type=positive_float, default=None,
                   help="meters per file unit, e.g. 0.01 for centimeters (default: inferred from the skeleton's "
                        "height; 'mmrl db info' shows it)")
    b.add_argument("--role", action="append", metavar="ROLE=JOINT",
                   help="name the joint of a role when it is not found by name, e.g. --role left_foot=LeftAnkle "
                        "(repeatable; roles: hips, left/right_upper_leg, _lower_leg, _foot, _toe)")
    add_import_arguments(b)
    t = b.add_argument_group("tags (docs/styles.md; the known datasets' naming and a top-level mmrl_tags.csv are read "
                             "unless --no-auto-tags)")
    t.add_argument("--tag-folder", metavar="GROUP", default=None,
                   help="tag each clip GROUP=<the folder its file sits in>, e.g. --tag-folder style")
    t.add_argument("--tag-pattern", metavar="PATTERN", action="append", default=[],
                   help="tag clips by their file names: {group} takes a part up to the next '_', {group:a|b} one "
                        "of the words, * anything; it must match the whole name without extension, e.g. "
                        "'dataset-2_{content}_{style}_*' (repeatable)")
    t.add_argument("--tag-file", metavar="FILE", action="append", default=[], dest="tag_file",
                   help="a sidecar file of tags: CSV lines 'file,tag tag ...' or JSON {file: [tags]} (repeatable)")
    deprecated_alias(t, "--tags", "--tag-file (train's --request-groups names tag groups)", "tag_file")
    t.add_argument("--no-auto-tags", action="store_true", help="only the tags the options above give")
    b.set_defaults(func=cmd_build)

    i = dsub.add_parser("info", help="print clips, frames, skeleton roles and feature statistics")
    i.add_argument("database", metavar="SOURCE", help="a database file, a BVH file or a folder of BVH files")
    add_import_arguments(i, " (when given BVH files)")
    i.set_defaults(func=cmd_info)


def add_import_arguments(parser, when: str = "") -> None:
    parser.add_argument("--up", choices=("auto", "y", "z"), default="auto",
                        help="the files' up axis; auto detects it per file from the hips and feet" + when)
    parser.add_argument("--fps", type=_fps, default=DEFAULT_FPS,
                        help=f"the database's frame rate; other rates are resampled (default {DEFAULT_FPS:g}; "
                             "0 keeps the files' rate)" + when)


def _fps(text: str) -> float:
    try:
        v = read_number(text, float, "a frame rate")
    except argparse.ArgumentTypeError:
        v = -1.0
    if not (v == 0 or 1 <= v <= 1000):
        raise argparse.ArgumentTypeError(f"expected a frame rate 1-1000 (or 0 to keep the files' rate), got {text!r}")
    return v


def import_options(args: argparse.Namespace) -> dict:
    return {"up": None if args.up == "auto" else args.up, "fps": args.fps or None}


def tag_rules(args: argparse.Namespace):
    """The TagRules of ``mmrl db build``'s tag options (ValueError on a bad pattern or group)."""
    from ..motion.tags import TagRules, compile_pattern

    for p in args.tag_pattern:
        try:
            compile_pattern(p)
        except ValueError as e:
            raise InputError(f"--tag-pattern: {e}") from None
    return TagRules(folder=args.tag_folder, patterns=tuple(args.tag_pattern), sidecars=tuple(args.tag_file),
                    auto=not args.no_auto_tags)


def cmd_build(args: argparse.Namespace) -> int:
    from ..motion.database import Database

    out = output_path(args.output, "-o")
    if out.suffix.lower() == ".bvh":
        raise InputError(f"-o {out}: the database is written there, not BVH; name it .npz")
    t0 = time.perf_counter()
    db = Database.from_bvh(args.data, mirror=args.mirror, scale=args.scale, roles=parse_roles(args.role),
                           progress=True, tags=tag_rules(args), **import_options(args))
    t1 = time.perf_counter()
    db.save(out)
    print(f"built {db.num_clips} clips ({int(db.clip_mirrored.sum())} mirrored), {db.num_frames:,} frames "
          f"({db.minutes:.1f} min at {fps_text(db.fps)} fps), {db.num_joints} joints, in {t1 - t0:.2f} s; saved "
          f"{out} in {time.perf_counter() - t1:.2f} s")
    print(unit_line(db, "as given by --scale" if args.scale else
                    "inferred from the skeleton's height; --scale overrides it"))
    for line in tag_lines(db):
        print(line)
    print(f"next: mmrl db info {out}, or mmrl train plane --db {out} --seconds 60")
    return 0


def fps_text(fps: float) -> str:
    """A frame rate as people write it: 30, 29.97, 59.94 (a file's 0.033333 s frame time is 30)."""
    return f"{round(fps, 2):g}"


def unit_line(db, how: str) -> str:
    """How the files' units became meters: the scale, the unit it stands for, and ``how``."""
    from ..motion.checks import unit_name

    return f"unit         {unit_name(db.source_scale)} (scale {db.source_scale:g} m per file unit, {how})"


def tag_lines(db) -> list:
    """``mmrl db info``'s lines on tags: each with its clips and frames, by group."""
    from ..motion.tags import tag_summary

    rows = tag_summary(db)
    if not rows:
        return ["tags         none (mmrl db build --tag-folder / --tag-pattern / --tag-file; docs/styles.md)"]
    lines = [f"tags         {len(rows)} in {len({t.partition('=')[0] for t, _, _ in rows})} groups "
             f"(request them as 'group=value & group=value')"]
    for tag, clips, frames in rows:
        lines.append(f"  {tag:<28} {clips:>5} clips {frames:>8} frames ({frames / db.fps / 60:.1f} min)")
    untagged = int((~db.clip_tags.any(axis=1)).sum())
    if untagged:
        lines.append(f"  (untagged: {untagged} clips)")
    return lines


def source_lines(db) -> list:
    """How the clips were imported, when it was not as-is: resampled rates, rotated up axes."""
    lines = []
    src = db.clip_source_fps
    other = np.abs(src - db.fps) > 1e-4 * db.fps
    if other.any():
        rates = ", ".join(fps_text(r) for r in np.unique(np.round(src[other], 3)))
        lines.append(f"source fps   {int(other.sum())} of {db.num_clips} clips resampled from {rates} fps "
                     f"to {fps_text(db.fps)} fps")
    z_up = db.clip_source_up == "z"
    if z_up.any():
        lines.append(f"up axis      {int(z_up.sum())} of {db.num_clips} clips were Z up, rotated to Y up")
    return lines


def cmd_info(args: argparse.Namespace) -> int:
    from ..motion.database import FEATURE_BLOCKS
    from ..metrics import raw_mocap_floor

    from ..motion.checks import is_database_file

    if is_database_file(args.database) and (args.fps != DEFAULT_FPS or args.up != "auto"):
        warn("--fps and --up apply to BVH input; a database keeps the rate and axes it was built with")
    db = load_any(args.database, **import_options(args))
    lengths = np.diff(db.clip_ranges, axis=1)[:, 0] / db.fps
    print(f"database     {args.database}")
    print(f"clips        {db.num_clips} ({int(db.clip_mirrored.sum())} mirrored), "
          f"length {lengths.min():.1f}-{lengths.max():.1f} s (median {np.median(lengths):.1f} s)")
    print(f"frames       {db.num_frames} at {fps_text(db.fps)} fps = {db.minutes:.1f} min; "
          f"{int(db.valid_mask.sum())} valid matches")
    print(unit_line(db, "given by --scale or inferred from the skeleton's height at build time"
                    if is_database_file(args.database) else "inferred from the skeleton's height"))
    for line in source_lines(db):
        print(line)
    for line in tag_lines(db):
        print(line)
    print(f"skeleton     {db.num_joints} joints")
    for role, joint in db.roles.items():
        print(f"  {role:<16} {joint}")
    floor = raw_mocap_floor(db)
    print(f"raw mocap    clips played straight (no matching, no IK): foot sliding "
          f"{floor['foot_sliding_cm_per_s']:.2f} cm/s (p95 {floor['foot_sliding_p95_cm_per_s']:.2f}) over contact "
          f"frames, pose jump p99 {floor['pose_jump_p99_cm']:.2f} cm (mmrl.metrics)")
    f = db.features[db.valid_mask]
    p, d = _core.TRAJECTORY_POSITION_COLUMNS[2], _core.TRAJECTORY_DIRECTION_COLUMNS[2]  # the +30-frame sample
    speed = np.hypot(f[:, p], f[:, p + 1])
    turn = np.degrees(np.arctan2(f[:, d], f[:, d + 1]))
    print(f"speed +1 s   median {np.median(speed):.2f} m/s, 5-95% {np.percentile(speed, 5):.2f}-"
          f"{np.percentile(speed, 95):.2f} m/s")
    print(f"turn +1 s    5-95% {np.percentile(turn, 5):.0f} to {np.percentile(turn, 95):.0f} deg")
    print(kinds_line(db))
    print("features     block                  weight  scale   columns: mean/std")
    scale = db.feature_scale
    w = db.weights
    for name, cols, _ in FEATURE_BLOCKS:
        stats = " ".join(f"{db.features[:, c].mean():+.2f}/{db.features[:, c].std():.2f}" for c in cols)
        print(f"             {name:<22} {w[name]:<7.2f} {scale[cols[0]] * w[name]:<7.3f} {stats}")
    return 0
