"""The README, as a newcomer meets it.

- ``## Two commands``: the first block installs and trains (one shell command), the second is
  exactly ``bash .ci/run``;
- the newcomer path ("From your data to your engine") fits the first screen, before any table;
- every ``mmrl ...`` line in the README's (and docs/tour.md's) code blocks parses with the real
  parser, without a deprecated spelling, so they never show a flag that does not exist;
- docs/cli.md names every option of every command, in that command's section;
- the newcomer path works: its commands, walked on synthetic BVH files with short budgets.

Optional extras the walk needs (imageio for the GIF, onnx for ``--onnx``) fail the test in CI
(``CI`` set; CI installs them) and elsewhere leave their step out, ending in a skip that says which.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import os
import re
import shlex
from pathlib import Path
from typing import List, Tuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
NEWCOMER = "## From your data to your engine"
# The README up to the end of the newcomer block: what it is, the two commands with the torch
# note, and the block itself. One screen and a half at most; today it is about 42 lines.
NEWCOMER_MAX_LINES = 50
# Pages whose code blocks must hold only commands that parse (the README's examples live there).
PARSED_PAGES = [README, ROOT / "docs" / "tour.md", ROOT / "docs" / "cli.md"]


# ------------------------------------------------------------------ reading markdown
class Block:
    def __init__(self, lang: str, start: int, end: int, lines: List[str]):
        self.lang, self.start, self.end, self.lines = lang, start, end, lines  # start/end: 1-based fence lines

    def commands(self) -> List[str]:
        """Logical lines: continuations (a trailing backslash) joined, blank lines dropped."""
        out, current = [], ""
        for line in self.lines:
            if line.rstrip().endswith("\\"):
                current += line.rstrip()[:-1] + " "
                continue
            current += line
            if current.strip():
                out.append(current.strip())
            current = ""
        if current.strip():
            out.append(current.strip())
        return out


def code_blocks(text: str) -> List[Block]:
    blocks, lines = [], text.splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if m:
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            assert j < len(lines), f"unclosed code block at line {i + 1}"
            blocks.append(Block(m.group(1), i + 1, j + 1, lines[i + 1:j]))
            i = j + 1
        else:
            i += 1
    return blocks


def section(text: str, heading: str) -> Tuple[int, int]:
    """1-based line range (heading line, last line) of a ``## `` section."""
    lines = text.splitlines()
    starts = [k for k, line in enumerate(lines) if line.strip() == heading]
    assert starts, f"the README has no {heading!r} heading"
    start = starts[0]
    end = next((k for k in range(start + 1, len(lines)) if lines[k].startswith("## ")), len(lines))
    return start + 1, end


def blocks_in(text: str, heading: str) -> List[Block]:
    lo, hi = section(text, heading)
    return [b for b in code_blocks(text) if lo < b.start <= hi]


def first_table_line(text: str):
    lines = text.splitlines()
    for k in range(len(lines) - 1):
        if lines[k].lstrip().startswith("|") and re.match(r"^\s*\|[\s:|-]+\|\s*$", lines[k + 1]) and "-" in lines[k + 1]:
            return k + 1
    return None


def mmrl_commands(logical_line: str) -> List[List[str]]:
    """The ``mmrl ...`` commands of one shell line (comments dropped; ``&&``, ``;``, ``|`` split)."""
    lexer = shlex.shlex(logical_line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    tokens = list(lexer)
    out, current = [], []
    for tok in tokens + [";"]:
        if tok and set(tok) <= set("&|;()"):
            if current and current[0] == "mmrl":
                out.append(current[1:])
            current = []
        else:
            current.append(tok)
    return out


README_TEXT = README.read_text(encoding="utf-8")


# ------------------------------------------------------------------ (a) the two commands
def test_two_commands():
    blocks = [b for b in blocks_in(README_TEXT, "## Two commands") if b.lang in ("bash", "sh", "")]
    assert len(blocks) >= 2, "## Two commands needs two bash blocks: install and train, then the tests"
    install, tests = blocks[0], blocks[1]
    text = " ".join(install.commands())
    assert "pip install" in text and "mmrl train" in text
    assert len(install.commands()) == 1, "the install-and-train block must stay one shell command (CI reads it so)"
    assert tests.lines == ["bash .ci/run"]


def test_install_text_says_which_torch():
    lo, hi = section(README_TEXT, "## Two commands")
    body = "\n".join(README_TEXT.splitlines()[lo - 1:hi])
    assert "download.pytorch.org/whl/cpu" in body and "CUDA" in body and "--device" in body


# ------------------------------------------------------------------ (b) the newcomer path, first screen
def test_newcomer_path_on_the_first_screen():
    blocks = blocks_in(README_TEXT, NEWCOMER)
    assert blocks, f"{NEWCOMER!r} has no code block"
    end = blocks[0].end
    table = first_table_line(README_TEXT)
    assert table is None or end < table, f"a table (line {table}) comes before the newcomer path ends (line {end})"
    assert end <= NEWCOMER_MAX_LINES, (f"the README takes {end} lines to the end of the newcomer path; keep it "
                                       f"within {NEWCOMER_MAX_LINES}")
    names = [" ".join(c[:2]) for line in blocks[0].commands() for c in mmrl_commands(line)]
    for step in ("db build", "db info", "train plane", "eval runs/mine", "play runs/mine", "render runs/mine",
                 "export runs/mine"):
        assert any(n.startswith(step.split()[0]) and step.split()[1] in n for n in names), (step, names)


def test_readme_has_no_internal_paths_or_issue_numbers():
    assert "../shared" not in README_TEXT
    assert not re.search(r"\bissues? \d+", README_TEXT, re.I)


def _extras() -> List[str]:
    """The extras of pyproject.toml (read by pattern: Python 3.9 has no tomllib)."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return re.findall(r"^(\w+)\s*=", block, re.M)


@pytest.mark.parametrize("extra", _extras())
def test_readme_names_the_extra(extra):
    assert f".[{extra}]" in README_TEXT or f"mmrl[{extra}]" in README_TEXT, f"the README does not list .[{extra}]"


# ------------------------------------------------------------------ (c) every command parses
def _page_commands():
    for page in PARSED_PAGES:
        for block in code_blocks(page.read_text(encoding="utf-8")):
            if block.lang not in ("bash", "sh", "console", ""):
                continue
            for line in block.commands():
                for argv in mmrl_commands(line):
                    yield pytest.param(argv, id=f"{page.name}:{block.start}:{' '.join(argv)[:60]}")


@pytest.mark.parametrize("argv", list(_page_commands()))
def test_documented_command_parses(argv):
    from mmrl.cli import build_parser

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            build_parser().parse_args(argv)
        except SystemExit as e:
            pytest.fail(f"mmrl {' '.join(argv)}: exit {e.code}: {err.getvalue().strip()}")
    assert "deprecated" not in err.getvalue(), f"mmrl {' '.join(argv)} uses an old spelling: {err.getvalue().strip()}"


def test_some_commands_were_found():
    assert sum(1 for _ in _page_commands()) >= 10


# ------------------------------------------------------------------ docs/cli.md: every option
def _leaf_parsers():
    from mmrl.cli import build_parser

    def walk(parser, name):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            yield name, parser
            return
        for sub_name, sub in subs[0].choices.items():
            yield from walk(sub, f"{name} {sub_name}".strip())

    return list(walk(build_parser(), ""))


def test_cli_page_names_every_option():
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    sections = re.split(r"^### ", text, flags=re.M)[1:]
    missing = []
    for name, parser in _leaf_parsers():
        mine = [s for s in sections if f"`mmrl {name}" in s.splitlines()[0] or
                re.search(rf"`{re.escape(name.split()[-1])}[ `]", s.splitlines()[0])]
        if not mine:
            missing.append(f"no section for mmrl {name}")
            continue
        body = "\n".join(mine)
        for action in parser._actions:
            if action.help == argparse.SUPPRESS or not action.option_strings or "--help" in action.option_strings:
                continue
            if not any(re.search(r"(?<![\w-])" + re.escape(o) + r"(?![\w-])", body) for o in action.option_strings):
                missing.append(f"mmrl {name} {'/'.join(action.option_strings)}")
    assert not missing, "docs/cli.md misses: " + ", ".join(missing)


# ------------------------------------------------------------------ (d) walk the newcomer path
def _have(module: str, extra: str) -> bool:
    try:
        importlib.import_module(module)
        return True
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail(f"{module} is missing; CI installs mmrl[{extra}]")
        return False


def _shorten(argv: List[str], bvh_dir: Path) -> List[str]:
    """The README's command with the user's folder replaced and short budgets."""
    out, k = [], 0
    while k < len(argv):
        a = argv[k]
        if a == "my_bvh_folder":
            out.append(str(bvh_dir))
        elif argv[0] == "train" and a == "--seconds":
            out += ["--steps", "2048"]
            k += 1
        elif argv[0] == "eval" and a == "--episodes":
            out += ["--episodes", "2"]
            k += 1
        elif argv[0] == "render" and a == "--length":
            out += ["--length", "0.5"]
            k += 1
        elif argv[0] == "render" and k > 0 and argv[k - 1] in ("-o", "--output"):
            out.append(str(Path(a).with_suffix(".gif")))
        else:
            out.append(a)
        k += 1
    if argv[0] == "train":
        out += ["--envs", "8", "--no-progress"]
    return out


def _outputs(argv: List[str]) -> List[Path]:
    paths = []
    for flag in ("-o", "--output", "--onnx"):
        if flag in argv:
            paths.append(Path(argv[argv.index(flag) + 1]))
    if argv[0] == "train" and "--out" in argv:
        paths.append(Path(argv[argv.index("--out") + 1]) / "latest.pt")
    return paths


def test_walk_the_newcomer_path(tmp_path, monkeypatch, capsys):
    from mmrl.cli import build_parser, main
    from mmrl.motion import synth

    bvh_dir = tmp_path / "my_bvh"
    synth.write_dataset(bvh_dir, num_clips=8, seconds_per_clip=4.0)
    monkeypatch.chdir(tmp_path)

    block = blocks_in(README_TEXT, NEWCOMER)[0]
    commands = [c for line in block.commands() for c in mmrl_commands(line)]
    assert commands, "the newcomer block holds no mmrl command"
    left_out, walked = [], []
    for argv in commands:
        if argv[0] == "play":  # a server: check that it parses and that its help shows
            with pytest.raises(SystemExit) as e:
                build_parser().parse_args(["play", "--help"])
            assert e.value.code == 0
            assert "usage: mmrl play" in capsys.readouterr().out
            walked.append("play --help")
            continue
        if argv[0] == "render" and not _have("imageio", "viz"):
            left_out.append("render (needs mmrl[viz])")
            continue
        if "--onnx" in argv and not (_have("onnx", "onnx") and _have("onnxruntime", "onnx")):
            left_out.append("export --onnx (needs mmrl[onnx])")
            continue
        run = _shorten(argv, bvh_dir)
        capsys.readouterr()
        rc = main(run)
        out = capsys.readouterr()
        assert rc == 0, f"mmrl {' '.join(run)} returned {rc}:\n{out.out[-2000:]}\n{out.err[-2000:]}"
        for path in _outputs(run):
            assert path.exists(), f"mmrl {' '.join(run)} did not write {path}"
        if run[0] == "eval":
            assert any(line.startswith("verdict:") for line in out.out.splitlines()), out.out
        if run[:2] == ["db", "info"]:
            assert "unit" in out.out and "hips" in out.out, out.out
        walked.append(" ".join(run[:2]))
    for step in ("db build", "db info", "train", "eval", "export"):
        assert any(w.startswith(step) for w in walked), f"the walk never ran mmrl {step}: {walked}"
    if left_out:
        pytest.skip("walked the newcomer path except " + "; ".join(left_out))
