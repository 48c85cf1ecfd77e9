"""Datasets: the cache directory and ``mmrl data fetch`` (checksummed, atomic, resumable downloads).

``mmrl data fetch bandai-namco-2 [--styles normal active ...]`` downloads the locomotion subset of
the Bandai Namco Research Motion Dataset 2 (962 BVH files, 199 MB, CC BY-NC 4.0, attribution
"Bandai Namco Research Inc.", non-commercial use only) into ``<cache>/bandai-namco-2/<style>/``.

Every file is checked against the size and SHA-256 in the checked-in manifest
``mmrl/manifests/bandai-namco-2.json`` (regenerate it with ``tools/make_bandai_manifest.py``):

- a download goes to a temporary file in the destination folder and is renamed into place only
  after its size and hash match, so an interrupted or corrupt download never leaves a file under
  the final name; a mismatch raises ``ChecksumError`` and keeps nothing;
- files already present with the right hash are skipped, so re-running resumes where it stopped.

Where files come from
---------------------
URLs are built from a template with the placeholders ``{base_url}``, ``{file}``, ``{style}`` and
``{content}``:

- upstream (the default): base URL ``UPSTREAM_BASE_URL`` (the repository's data folder at commit
  74ead3b, where all files sit in one flat folder) with template ``UPSTREAM_URL_TEMPLATE`` =
  ``{base_url}/{file}``;
- a mirror of our cache layout (``<style>/<file>``, as in ../shared/data/bandai-namco-2): template
  ``STYLE_DIR_URL_TEMPLATE`` = ``{base_url}/{style}/{file}``.

Override with ``--base-url`` / ``$MMRL_DATA_URL`` and ``--url-template`` / ``$MMRL_DATA_URL_TEMPLATE``
(arguments win over the environment). ``file://`` URLs work too.

The cache root is ``$MMRL_CACHE`` if set, else ``$XDG_CACHE_HOME/mmrl``, else ``~/.cache/mmrl``.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import urllib.error
import urllib.request
from importlib import resources
from pathlib import Path
from typing import Iterable, List, Optional, Sequence

from ..errors import InputError
from ..io import atomic_open, atomic_write_text, remove_stale_temps

__all__ = [
    "DATASETS",
    "UPSTREAM_BASE_URL",
    "UPSTREAM_URL_TEMPLATE",
    "STYLE_DIR_URL_TEMPLATE",
    "ChecksumError",
    "DownloadError",
    "cache_root",
    "dataset_manifest",
    "fetch",
    "register_cli",
]

DATASETS = ("bandai-namco-2",)
UPSTREAM_BASE_URL = ("https://github.com/BandaiNamcoResearchInc/Bandai-Namco-Research-Motiondataset/raw/"
                     "74ead3b/dataset/Bandai-Namco-Research-Motiondataset-2/data")
UPSTREAM_URL_TEMPLATE = "{base_url}/{file}"
STYLE_DIR_URL_TEMPLATE = "{base_url}/{style}/{file}"
_CHUNK = 1 << 16


class ChecksumError(ValueError):
    """A downloaded file's size or SHA-256 differs from the manifest; nothing was kept."""


class DownloadError(OSError):
    """A file could not be downloaded (HTTP error, connection failure, timeout)."""


def cache_root() -> Path:
    """Root of mmrl's cache: ``$MMRL_CACHE``, else ``$XDG_CACHE_HOME/mmrl``, else ``~/.cache/mmrl``."""
    env = os.environ.get("MMRL_CACHE")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "mmrl"


def dataset_manifest(name: str = "bandai-namco-2") -> dict:
    """The checked-in manifest of a dataset: upstream, license, and per file name, style, content,
    size (bytes) and sha256."""
    _check_dataset(name)
    text = resources.files("mmrl").joinpath("manifests").joinpath(f"{name}.json").read_text(encoding="utf-8")
    return json.loads(text)


def _check_dataset(name: str) -> None:
    if name not in DATASETS:
        raise InputError(f"unknown dataset {name!r}; known: {', '.join(DATASETS)}")


def _select(manifest: dict, styles: Optional[Iterable[str]], contents: Optional[Iterable[str]]) -> List[dict]:
    files = manifest["files"]
    chosen = []
    for key, wanted in (("style", styles), ("content", contents)):
        if wanted is None:
            continue
        wanted = list(wanted)
        known = sorted({f[key] for f in files})
        unknown = [w for w in wanted if w not in known]
        if unknown or not wanted:
            raise InputError(f"unknown {key}(s) {unknown or wanted!r} for {manifest['dataset']}; known: {', '.join(known)}")
        chosen.append((key, set(wanted)))
    return [f for f in files if all(f[key] in wanted for key, wanted in chosen)]


def _sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(_CHUNK), b""):
            h.update(block)
    return h.hexdigest()


def _is_valid(path: Path, entry: dict) -> bool:
    return path.is_file() and path.stat().st_size == entry["size"] and _sha256_of(path) == entry["sha256"]


def _download(url: str, dest: Path, entry: dict, timeout: float, progress) -> None:
    """Stream `url` into a temporary file next to `dest`, verify size and hash, rename into place."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    # The temp file of a download killed earlier (SIGKILL, power loss) stays behind, hidden; an
    # active download writes a block at least every `timeout` seconds, so older ones are stale.
    remove_stale_temps(dest, min_age_s=max(60.0, 2 * timeout))
    # atomic_open keeps nothing when the block raises: a failed or mismatched download never
    # replaces (or creates) dest.
    with atomic_open(dest, "wb") as out:
        h = hashlib.sha256()
        size = 0
        try:
            with urllib.request.urlopen(url, timeout=timeout) as response:
                while True:
                    block = response.read(_CHUNK)
                    if not block:
                        break
                    size += len(block)
                    if size > entry["size"]:
                        break  # longer than expected: no need to read the rest
                    h.update(block)
                    out.write(block)
                    progress.update(len(block))
        except (urllib.error.URLError, OSError) as e:  # HTTPError is a URLError
            raise DownloadError(f"could not download {url}: {e}") from e
        if size != entry["size"] or h.hexdigest() != entry["sha256"]:
            got = f"{size}+ bytes" if size > entry["size"] else f"{size} bytes, sha256 {h.hexdigest()}"
            raise ChecksumError(
                f"checksum mismatch for {entry['name']} from {url}: expected {entry['size']} bytes, "
                f"sha256 {entry['sha256']}; got {got}. The file was not kept; check the URL "
                f"(--base-url / --url-template) or retry.")


def fetch(name: str = "bandai-namco-2", *, styles: Optional[Sequence[str]] = None,
          contents: Optional[Sequence[str]] = None, dest: Optional[os.PathLike] = None,
          base_url: Optional[str] = None, url_template: Optional[str] = None,
          timeout: float = 60.0, progress: bool = True) -> Path:
    """Download a dataset (or some of its styles / contents) into the cache and verify it.

    name: a dataset in ``DATASETS``. styles, contents: subsets to fetch (default: all), e.g.
    ``styles=["normal"]``, ``contents=["walk", "run"]``; unknown values raise ValueError.
    dest: the dataset folder (default ``cache_root() / name``); files land in ``dest/<style>/<file>``.
    base_url, url_template: where to download from (default ``$MMRL_DATA_URL`` or the upstream
    repository, and ``$MMRL_DATA_URL_TEMPLATE`` or ``{base_url}/{file}``); see the module docs.
    timeout: seconds per connection attempt. progress: show a tqdm progress bar (bytes).

    Returns the dataset folder. Files that are already present with the right SHA-256 are not
    downloaded again. Raises ChecksumError on a size or hash mismatch (the bad file is not kept)
    and DownloadError when a file cannot be downloaded.
    """
    _check_dataset(name)
    manifest = dataset_manifest(name)
    entries = _select(manifest, styles, contents)
    base_url = (base_url or os.environ.get("MMRL_DATA_URL") or UPSTREAM_BASE_URL).rstrip("/")
    url_template = url_template or os.environ.get("MMRL_DATA_URL_TEMPLATE") or UPSTREAM_URL_TEMPLATE
    try:
        url_template.format(base_url="", file="", style="", content="")
    except (KeyError, IndexError, ValueError) as e:
        raise InputError(f"bad URL template {url_template!r}: placeholders are {{base_url}}, {{file}}, "
                         f"{{style}}, {{content}}") from e
    root = Path(dest) if dest is not None else cache_root() / name

    from tqdm import tqdm  # imported here: only fetching needs it

    todo = [e for e in entries if not _is_valid(root / e["style"] / e["name"], e)]
    with tqdm(total=sum(e["size"] for e in todo), unit="B", unit_scale=True, disable=not progress,
              desc=f"{name}: {len(todo)} of {len(entries)} files") as bar:
        for entry in todo:
            url = url_template.format(base_url=base_url, file=entry["name"], style=entry["style"],
                                      content=entry["content"])
            _download(url, root / entry["style"] / entry["name"], entry, timeout, bar)
    notice = root / "NOTICE.txt"
    if not notice.exists():
        notice.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(notice,
            f"{manifest['title']}\nUpstream: https://github.com/{manifest['upstream']['repository']} "
            f"(commit {manifest['upstream']['commit']}, {manifest['upstream']['folder']})\n"
            f"License: {manifest['license']}, attribution: {manifest['attribution']}. Non-commercial use only.\n"
            f"Downloaded by mmrl; layout <style>/<file>; every file checked against its SHA-256.\n")
    return root


# ---------------------------------------------------------------------------------------------
# CLI: `mmrl data fetch ...`
# ---------------------------------------------------------------------------------------------
def register_cli(subparsers) -> None:
    """Add the ``data`` command (with its ``fetch`` subcommand) to an argparse subparsers object.

    The handler is stored as ``func`` in the parsed namespace: ``args.func(args)`` returns an
    exit code (0 on success, 1 on a download or checksum error, after printing the message).
    """
    data = subparsers.add_parser("data", help="download datasets into the cache",
                                 description="Download motion datasets into mmrl's cache.")
    data_sub = data.add_subparsers(dest="data_command", metavar="COMMAND")
    data_sub.required = True
    manifest_styles = sorted({f["style"] for f in dataset_manifest("bandai-namco-2")["files"]})
    fetch_parser = data_sub.add_parser(
        "fetch", help="download and verify a dataset",
        description="Download a dataset into the cache, verifying every file's SHA-256. "
                    "Files already present are skipped.")
    fetch_parser.add_argument("dataset", choices=DATASETS)
    fetch_parser.add_argument("--styles", nargs="+", metavar="STYLE", choices=manifest_styles,
                              help=f"only these styles (default: all of {', '.join(manifest_styles)})")
    fetch_parser.add_argument("--contents", nargs="+", metavar="CONTENT",
                              help="only these contents (walk, walk-turn-left, walk-turn-right, run)")
    fetch_parser.add_argument("--dest", help="dataset folder (default: <cache>/<dataset>)")
    fetch_parser.add_argument("--base-url", help="download from here (default: $MMRL_DATA_URL or upstream)")
    fetch_parser.add_argument("--url-template",
                              help="URL pattern with {base_url}, {file}, {style}, {content} "
                                   "(default: $MMRL_DATA_URL_TEMPLATE or '{base_url}/{file}'; "
                                   "a mirror of the cache layout: '{base_url}/{style}/{file}')")
    fetch_parser.add_argument("--timeout", type=_seconds, default=60.0, help="seconds per connection (default 60)")
    fetch_parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    fetch_parser.set_defaults(func=_fetch_command)


def _seconds(text: str) -> float:
    import argparse
    import math

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"expected a number of seconds > 0, got {text!r}")
    return value


def _fetch_command(args) -> int:
    try:
        root = fetch(args.dataset, styles=args.styles, contents=args.contents, dest=args.dest,
                     base_url=args.base_url, url_template=args.url_template, timeout=args.timeout,
                     progress=not args.no_progress)
    except (ChecksumError, DownloadError, ValueError) as e:
        print(f"mmrl data fetch: error: {e}", file=sys.stderr)
        return 1
    print(f"{args.dataset}: ready in {root} (CC BY-NC 4.0, Bandai Namco Research Inc.; non-commercial use only)")
    return 0
