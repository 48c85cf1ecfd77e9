"""Tags on clips (issue 26): where they come from when a database is built.

A tag is ``group=value`` (``style=elderly``, ``gait=walk``). A database carries a set of tags per
clip (``Database.tag_names``, ``Database.clip_tags``), saved in its file and in the runtime's
file; a mirrored clip keeps its original's tags. Requests over them (``"style=elderly & gait=walk"``)
restrict matching to the clips carrying them: the C++ rule of ``cpp/include/mmrl/tags.hpp``.

Tags come from, in this order (all of them add up):

- **the folder** a clip sits in: ``TagRules(folder="style")`` tags every clip ``style=<the name of
  the folder holding its file>`` (``mmrl db build --tag-folder style``);
- **patterns over file names**: ``{group}`` takes a part of the name up to the next ``_``,
  ``{group:a|b}`` one of the listed words, ``*`` anything; the pattern must match the whole name
  without its extension. Bandai-Namco's ``dataset-2_<content>_<style>_<NNN>.bvh`` is
  ``dataset-2_{content}_{style}_*``, and ``dataset-2_{gait:walk|run}*`` gives the gait of
  ``walk-turn-left`` (``--tag-pattern``);
- **sidecar files** that a user writes (``--tag-file FILE``): CSV lines ``file,tag tag ...`` (tags
  separated by spaces or ``;``, an optional ``file,tags`` header, ``#`` comments) or JSON
  (``{"file": ["tag", ...]}`` or ``[{"file": ..., "tags": [...]}]``). A file is named by its
  path relative to the data folder, its file name, or its name without extension;
- **automatically** (unless ``auto=False``, ``--no-auto-tags``): the known datasets' own naming
  (:data:`AUTO_PATTERNS`: Bandai-Namco's, the package's synthetic clips'), and a sidecar named
  ``mmrl_tags.csv`` or ``mmrl_tags.json`` at the top of a data folder.
"""
from __future__ import annotations

import csv
import io
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..errors import InputError

PathLike = Union[str, "os.PathLike[str]"]

#: The naming of the datasets mmrl knows: applied to the files whose names they match.
AUTO_PATTERNS: Tuple[str, ...] = (
    "dataset-2_{content}_{style}_*",        # Bandai-Namco Research Motion Dataset 2
    "dataset-2_{gait:walk|run}*",
    "synth_*_{content}",                    # the package's synthetic clips (mmrl.motion.synth)
    "synth_*_{gait:walk|run}*",
)
#: Sidecar names read from the top of a data folder when ``auto`` is on.
AUTO_SIDECARS: Tuple[str, ...] = ("mmrl_tags.csv", "mmrl_tags.json")

_WORD = re.compile(r"^[A-Za-z0-9_.\-]+$")


class TagFileError(InputError):
    """A sidecar tag file is malformed or names a clip the data does not have (the message
    gives the file and line)."""


def tag_value(name: str) -> str:
    """A folder or file-name part as a tag value: runs of spaces and other characters a tag
    cannot hold become one ``_`` (``Slow Walk`` -> ``Slow_Walk``)."""
    return re.sub(r"[^A-Za-z0-9_.\-]+", "_", str(name)).strip("_")


def check_tag(tag: str, where: str = "tag") -> str:
    """``tag`` stripped, if it is ``group=value`` (letters, digits, ``_-.``); else ValueError."""
    t = str(tag).strip()
    g, eq, v = t.partition("=")
    if not eq or not _WORD.match(g) or not _WORD.match(v):
        raise ValueError(f"{where}: {tag!r} is not group=value (letters, digits, '_', '-', '.')")
    return t


def compile_pattern(pattern: str) -> "re.Pattern[str]":
    """A file-name pattern (see the module docstring) as a regular expression over the stem."""
    out, i, groups = [], 0, set()
    while i < len(pattern):
        c = pattern[i]
        if c == "{":
            j = pattern.find("}", i)
            if j < 0:
                raise ValueError(f"tag pattern {pattern!r}: '{{' without '}}'")
            name, _, alts = pattern[i + 1:j].partition(":")
            if not name.isidentifier():
                raise ValueError(f"tag pattern {pattern!r}: {{{name}}} is not a group name (letters, digits, '_')")
            if name in groups:
                raise ValueError(f"tag pattern {pattern!r}: group {name!r} appears twice")
            groups.add(name)
            if alts:
                words = alts.split("|")
                if not all(_WORD.match(w) for w in words):
                    raise ValueError(f"tag pattern {pattern!r}: {{{name}:{alts}}} must list words separated by '|'")
                body = "|".join(re.escape(w) for w in words)
            else:
                body = r"[^_/\\]+"
            out.append(f"(?P<{name}>{body})")
            i = j + 1
        elif c == "*":
            out.append(".*")
            i += 1
        else:
            out.append(re.escape(c))
            i += 1
    if not groups:
        raise ValueError(f"tag pattern {pattern!r} has no {{group}}: it would give no tag")
    return re.compile("".join(out))


@dataclass
class TagRules:
    """Where a database build takes its tags from (see the module docstring)."""

    folder: Optional[str] = None
    patterns: Sequence[str] = ()
    sidecars: Sequence[PathLike] = ()
    auto: bool = True


def _names(path: Path, roots: Sequence[Path]) -> List[str]:
    """The names a sidecar may use for a file: relative paths under each root, file name, stem."""
    out = []
    for r in roots:
        try:
            out.append(path.resolve().relative_to(r.resolve()).as_posix())
        except ValueError:
            pass
    out += [path.name, path.stem, path.as_posix()]
    return out


def _parse_csv(path: Path) -> List[Tuple[int, str, List[str]]]:
    rows = []
    text = path.read_text(encoding="utf-8")
    for lineno, row in enumerate(csv.reader(io.StringIO(text)), start=1):
        if not row or not "".join(row).strip() or row[0].strip().startswith("#"):
            continue
        if lineno == 1 and [c.strip().lower() for c in row[:2]] == ["file", "tags"]:
            continue
        if len(row) < 2 or not row[0].strip():
            raise TagFileError(f"{path}:{lineno}: expected 'file,tags', got {','.join(row)!r}")
        tags = [t for cell in row[1:] for t in re.split(r"[;\s]+", cell) if t]
        rows.append((lineno, row[0].strip(), tags))
    return rows


def _parse_json(path: Path) -> List[Tuple[int, str, List[str]]]:
    text = path.read_text(encoding="utf-8")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise TagFileError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None

    def line_of(key: str) -> int:  # the line a key first appears on, for messages
        k = text.find(json.dumps(key))
        return text.count("\n", 0, k) + 1 if k >= 0 else 1

    items = []
    if isinstance(data, dict):
        items = [(line_of(k), k, v) for k, v in data.items()]
    elif isinstance(data, list):
        for n, entry in enumerate(data):
            if not isinstance(entry, dict) or "file" not in entry or "tags" not in entry:
                raise TagFileError(f"{path}: entry {n}: expected {{\"file\": ..., \"tags\": [...]}}")
            items.append((line_of(str(entry["file"])), str(entry["file"]), entry["tags"]))
    else:
        raise TagFileError(f"{path}:1: expected an object {{file: [tags]}} or a list of {{file, tags}}")
    rows = []
    for lineno, name, tags in items:
        if isinstance(tags, str):
            tags = re.split(r"[;\s]+", tags)
        if not isinstance(tags, list) or not all(isinstance(t, str) for t in tags):
            raise TagFileError(f"{path}:{lineno}: the tags of {name!r} must be a list of strings")
        rows.append((lineno, name, [t for t in tags if t]))
    return rows


def read_sidecar(path: PathLike) -> List[Tuple[int, str, List[str]]]:
    """``(line, file name, tags)`` rows of a sidecar file (TagFileError naming file and line)."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such tag file")
    rows = _parse_json(p) if p.suffix.lower() == ".json" else _parse_csv(p)
    for lineno, _, tags in rows:
        for t in tags:
            try:
                check_tag(t)
            except ValueError as e:
                raise TagFileError(f"{p}:{lineno}: {e}") from None
    return rows


def clip_tags_for_files(files: Sequence[PathLike], roots: Sequence[PathLike] = (),
                        rules: Optional[TagRules] = None) -> Tuple[List[str], np.ndarray]:
    """The tags of each file: ``(tag names, (len(files), T) uint8 matrix)``, tag names sorted by
    group, then value."""
    rules = rules or TagRules()
    paths = [Path(f) for f in files]
    root_dirs = [Path(r) for r in roots if Path(r).is_dir()]
    per_file: List[set] = [set() for _ in paths]
    if rules.folder:
        try:
            g = check_tag(f"{rules.folder}=x", "--tag-folder").partition("=")[0]
        except ValueError as e:
            raise InputError(f"{e}: name a group, e.g. --tag-folder style") from None
        for k, p in enumerate(paths):
            value = tag_value(p.parent.name)
            if not value:
                raise InputError(f"--tag-folder {g}: the folder of {p} has no letters or digits to make a tag of")
            per_file[k].add(f"{g}={value}")
    patterns = [(s, compile_pattern(s), True) for s in rules.patterns]
    if rules.auto:
        patterns += [(s, compile_pattern(s), False) for s in AUTO_PATTERNS]
    for text, rx, own in patterns:
        hits = 0
        for k, p in enumerate(paths):
            m = rx.fullmatch(p.stem)
            if m:
                hits += 1
                per_file[k].update(f"{g}={tag_value(v) or v}" for g, v in m.groupdict().items())
        if own and not hits and paths:
            raise InputError(f"--tag-pattern {text!r} matches none of the {len(paths)} files (names such as "
                             f"{paths[0].stem!r}); it must match a whole name without its extension")
    sidecars = [Path(s) for s in rules.sidecars]
    if rules.auto:
        sidecars = [r / n for r in root_dirs for n in AUTO_SIDECARS if (r / n).is_file()] + sidecars
    if sidecars:
        index: Dict[str, List[int]] = {}
        for k, p in enumerate(paths):
            for n in set(_names(p, root_dirs)):
                index.setdefault(n, []).append(k)
        for sc in sidecars:
            for lineno, name, tags in read_sidecar(sc):
                hits = index.get(name) or index.get(Path(name).as_posix())
                if not hits:
                    raise TagFileError(f"{sc}:{lineno}: no clip {name!r} among the {len(paths)} files of the data")
                for k in hits:
                    per_file[k].update(check_tag(t) for t in tags)
    names = sorted({t for tags in per_file for t in tags}, key=lambda t: tuple(t.partition("=")[::2]))
    matrix = np.zeros((len(paths), len(names)), np.uint8)
    col = {t: i for i, t in enumerate(names)}
    for k, tags in enumerate(per_file):
        for t in tags:
            matrix[k, col[t]] = 1
    return names, matrix


def request_group_list(spec) -> List[str]:
    """A task's ``request_groups`` ("style,gait" or a list) as a list of group names."""
    if isinstance(spec, str):
        return [g.strip() for g in spec.split(",") if g.strip()]
    return [str(g) for g in (spec or ())]


def tag_summary(db) -> List[Tuple[str, int, int]]:
    """``(tag, clips, frames)`` per tag of a database, in its order."""
    lengths = np.diff(np.asarray(db.clip_ranges), axis=1)[:, 0]
    tags = np.asarray(db.clip_tags, bool)
    return [(t, int(tags[:, k].sum()), int(lengths[tags[:, k]].sum())) for k, t in enumerate(db.tag_names)]
