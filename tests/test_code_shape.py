"""The shape of the code: no module over 500 lines, no function over 80 lines (issue 13).

Checked on ``python/mmrl/**/*.py`` and on ``cpp/src``, ``cpp/include``, ``cpp/bindings``, ``cpp/runtime``, ``examples``
(``*.cpp``, ``*.hpp``). Exceptions are allowed where a comment says why:

- a module may exceed 500 lines if one of its first 40 lines holds a comment starting ``size:``
  with a reason (``# size: one parser, split it and the state machine spreads``, or ``// size: ...``);
- a function may exceed 80 lines if a comment starting ``long:`` with a reason is on one of the
  3 lines above its definition, on its decorator lines or on the definition line itself.

A function's length runs from its first line (``def``; in C++ the signature, ``template <...>``
included) to its last line, both included. Python functions are found with ``ast``; nested
functions count on their own (and inside their parent). C++ functions are found by a small
scanner below: comments, string and character literals and preprocessor lines are blanked out,
then a ``{`` at namespace or class scope whose header (the text since the previous ``;``, ``{`` or
``}``) holds a parameter list opens a function body, which runs to the matching ``}``. Everything
inside a body (lambdas, local classes, blocks) belongs to that function. The scanner is tested
below against hand-counted answers on small sources.
"""
from __future__ import annotations

import ast
import bisect
import io
import re
import tokenize
import warnings
from pathlib import Path
from typing import List, NamedTuple, Optional

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
SIZE_HEAD_LINES = 40  # a `size:` comment must be within the module's first 40 lines
LONG_LOOKBACK = 3  # a `long:` comment may be up to 3 lines above the definition
CPP_DIRS = ("cpp/src", "cpp/include", "cpp/bindings", "cpp/runtime", "examples")
CPP_SUFFIXES = (".cpp", ".hpp")

# A comment whose text starts with the tag and a non-empty reason ("# size:" alone does not count).
_SIZE_RE = re.compile(r"^(?:#|//|/\*)\s*size:\s*\S")
_LONG_RE = re.compile(r"^(?:#|//|/\*)\s*long:\s*\S")


class Function(NamedTuple):
    name: str
    first: int  # 1-based line of the definition (Python: the `def`; C++: the signature start)
    last: int  # 1-based line of the last line of the body
    comment_from: int  # first line where a `long:` comment may stand (decorators, lookback)

    @property
    def length(self) -> int:
        return self.last - self.first + 1


# ------------------------------------------------------------------------------------------
# Python
# ------------------------------------------------------------------------------------------
def python_comments(source: str) -> dict:
    """{line: comment text} for every ``#`` comment (real comments only, not text in strings)."""
    out = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            out[tok.start[0]] = tok.string
    return out


def python_functions(source: str) -> List[Function]:
    with warnings.catch_warnings():  # an invalid escape in the source is not this test's business
        warnings.simplefilter("ignore")
        tree = ast.parse(source)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            top = min([node.lineno] + [d.lineno for d in node.decorator_list])
            out.append(Function(node.name, node.lineno, node.end_lineno, top - LONG_LOOKBACK))
    return sorted(out, key=lambda f: f.first)


# ------------------------------------------------------------------------------------------
# C++
# ------------------------------------------------------------------------------------------
_RAW_PREFIX_RE = re.compile(r"(?:^|[^A-Za-z0-9_])(?:u8|u|U|L)?R$")
_IDENT_CHAR = re.compile(r"[A-Za-z0-9_.]")


def _blank(chars: list, start: int, stop: int) -> None:
    for k in range(start, stop):
        if chars[k] != "\n":
            chars[k] = " "


def mask_cpp(source: str) -> str:
    """The source with comments, string and character literals and preprocessor lines replaced
    by spaces (newlines kept, so offsets and line numbers are unchanged)."""
    return _scan_cpp(source)[0]


def cpp_comments(source: str) -> dict:
    """{line: text of the first comment starting on that line, from its `//` or `/*`}."""
    return _scan_cpp(source)[1]


def _scan_cpp(source: str):
    chars = list(source)
    comments = {}
    n = len(source)
    i = 0
    line, line_start = 1, True  # line_start: only whitespace so far on this line
    while i < n:
        c = source[i]
        if c == "\n":
            line, line_start = line + 1, True
            i += 1
            continue
        if c in " \t\r\f\v":
            i += 1
            continue
        if c == "#" and line_start:  # preprocessor directive, with backslash continuations
            j = i
            while j < n and not (source[j] == "\n" and source[j - 1] != "\\"):
                j += 1
        elif source.startswith("//", i) or source.startswith("/*", i):
            if source[i + 1] == "/":
                j = source.find("\n", i)
                j = n if j < 0 else j
            else:
                j = source.find("*/", i + 2)
                j = n if j < 0 else j + 2
            comments.setdefault(line, source[i:j])
        elif c == '"' and _RAW_PREFIX_RE.search(source[max(0, i - 3):i]):
            paren = source.find("(", i)
            delimiter = ")" + source[i + 1:paren] + '"'
            j = source.find(delimiter, paren)
            j = n if j < 0 else j + len(delimiter)
        elif c == '"' or (c == "'" and not _is_digit_separator(source, i)):
            j = i + 1
            while j < n and source[j] != c and source[j] != "\n":
                j += 2 if source[j] == "\\" else 1
            j = min(j + 1, n)
        else:
            line_start = False
            i += 1
            continue
        line_start = False
        line += source.count("\n", i, j)
        _blank(chars, i, j)
        i = j
    return "".join(chars), comments


def _is_digit_separator(source: str, i: int) -> bool:
    """True for the quote in 1'000'000 (C++14): the token it sits in starts with a digit."""
    k = i
    while k > 0 and (_IDENT_CHAR.match(source[k - 1]) or source[k - 1] == "'"):
        k -= 1
    return k < i and source[k].isdigit()


def _matching_brace(masked: str, i: int) -> int:
    depth = 0
    for j in range(i, len(masked)):
        if masked[j] == "{":
            depth += 1
        elif masked[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    raise ValueError(f"unbalanced '{{' at offset {i}")


_ACCESS_RE = re.compile(r"^(?:\s*(?:public|private|protected)\s*:(?!:))+")
_TEMPLATE_RE = re.compile(r"^template\s*<")
_NON_SPACE = re.compile(r"\S")
_CONTROL = {"if", "for", "while", "switch", "catch", "do", "else", "try", "return"}


def _classify(header: str) -> str:
    """'namespace', 'class' (its body is scanned for member functions), 'function' or 'other'
    (an enum, an initializer: skipped whole)."""
    h = " ".join(header.split())
    if re.match(r"^(?:inline )?namespace\b", h) or re.match(r"^extern\s*$", h):
        return "namespace"  # `extern "C" {` reads `extern` once its string is blanked
    if _TEMPLATE_RE.match(h):  # drop `template <...>` (balanced angle brackets)
        depth, k = 0, h.index("<")
        for k in range(k, len(h)):
            depth += {"<": 1, ">": -1}.get(h[k], 0)
            if depth == 0:
                break
        h = h[k + 1:].strip()
    if re.match(r"^(?:typedef )?(?:class|struct|union)\b", h):
        return "class"
    if re.match(r"^enum\b", h):
        return "other"
    first_word = re.match(r"^\w*", h).group(0)
    if "(" in h and ")" in h and first_word not in _CONTROL and not re.search(r"[=,(\[]$", h):
        return "function"
    return "other"


def _function_name(header: str) -> str:
    before = header[:header.index("(")] if "(" in header else header
    if re.search(r"\boperator\s*\S*\s*$", before):  # operator(), operator==, ...
        return "operator" + before.rsplit("operator", 1)[1].strip()
    names = re.findall(r"[A-Za-z_~][\w:~]*", before)
    return names[-1] if names else "?"


def cpp_functions(source: str) -> List[Function]:
    """Function bodies at namespace or class scope, with their first and last lines."""
    masked = mask_cpp(source)
    line_of = _line_index(masked)
    out = []
    segment = 0  # start of the current declaration's text
    i, n = 0, len(masked)
    while i < n:
        c = masked[i]
        if c in ";}":
            segment = i + 1
        elif c == "{":
            header = _ACCESS_RE.sub("", masked[segment:i]).lstrip()
            kind = _classify(header)
            if kind in ("namespace", "class"):
                segment = i + 1  # scan the inside: its `}` closes it like any other
            else:
                close = _matching_brace(masked, i)
                nxt = _NON_SPACE.search(masked, close + 1)
                after = nxt.group(0) if nxt else ""
                # A brace followed by `,`, `{`, `(` or `)` is a member initializer (`x_{a},
                # y_{b} {`) or a lambda called in one (`tree_([&] {...}()) {`), not the body:
                # the declaration goes on. Other braces (enums, initializers) are skipped whole
                # and their declaration ends at the next `;`.
                if kind == "function" and after not in (",", "{", "(", ")"):
                    start = i - len(header)
                    out.append(Function(_function_name(header), line_of(start), line_of(close),
                                        line_of(start) - LONG_LOOKBACK))
                    segment = close + 1
                i = close + 1
                continue
        i += 1
    return out


def _line_index(text: str):
    """A function from a character offset to its 1-based line."""
    starts = [0] + [k + 1 for k, ch in enumerate(text) if ch == "\n"]
    return lambda offset: bisect.bisect_right(starts, offset)


# ------------------------------------------------------------------------------------------
# The check
# ------------------------------------------------------------------------------------------
def check_file(path: Path, relative: str) -> List[str]:
    """Offenders in one file, each as ``file:line: what (length)``."""
    source = path.read_text(encoding="utf-8")
    is_python = path.suffix == ".py"
    comments = python_comments(source) if is_python else cpp_comments(source)
    functions = python_functions(source) if is_python else cpp_functions(source)
    return offenders(relative, source, comments, functions)


def offenders(relative: str, source: str, comments: dict, functions: List[Function]) -> List[str]:
    out = []
    num_lines = len(source.splitlines())
    if num_lines > MAX_MODULE_LINES and not _tagged(comments, 1, SIZE_HEAD_LINES, _SIZE_RE):
        out.append(f"{relative}:1: module of {num_lines} lines (> {MAX_MODULE_LINES}, "
                   f"no `size:` comment in its first {SIZE_HEAD_LINES} lines)")
    for f in functions:
        if f.length > MAX_FUNCTION_LINES and not _tagged(comments, f.comment_from, f.first, _LONG_RE):
            out.append(f"{relative}:{f.first}: function {f.name} of {f.length} lines (> {MAX_FUNCTION_LINES}, "
                       f"no `long:` comment above it)")
    return out


def _tagged(comments: dict, first: int, last: int, pattern: re.Pattern) -> bool:
    return any(pattern.match(comments[k].strip()) for k in range(first, last + 1) if k in comments)


def source_files() -> List[Path]:
    files = sorted((ROOT / "python" / "mmrl").rglob("*.py"))
    for d in CPP_DIRS:
        files += sorted(p for p in (ROOT / d).rglob("*") if p.suffix in CPP_SUFFIXES)
    return files


def all_offenders() -> List[str]:
    out = []
    for path in source_files():
        out += check_file(path, str(path.relative_to(ROOT)))
    return out


def test_no_module_over_500_lines_and_no_function_over_80_lines():
    files = source_files()
    assert any(p.suffix == ".py" for p in files) and any(p.suffix in CPP_SUFFIXES for p in files)
    found = all_offenders()
    assert not found, (f"{len(found)} offender(s); split them, or say why in a `size:` / `long:` comment "
                       f"(see tests/test_code_shape.py):\n" + "\n".join(found))


# ------------------------------------------------------------------------------------------
# The scanner against hand-counted answers
# ------------------------------------------------------------------------------------------
def spans(source: str):
    return [(f.name, f.first, f.last) for f in cpp_functions(source)]


def test_scanner_three_line_function():
    assert spans("int f(int a) {\n  return a;\n}\n") == [("f", 1, 3)]
    assert cpp_functions("int f(int a) {\n  return a;\n}\n")[0].length == 3


def test_scanner_lambda_and_string_with_braces_stay_in_their_function():
    src = (
        "#include <string>\n"                          # 1
        "static int g(int x) { return x; }\n"          # 2
        "std::string f(int n) {\n"                     # 3
        "  auto add = [&](int k) {\n"                  # 4
        "    return k + n;\n"                          # 5
        "  };\n"                                       # 6
        "  const char* s = \"}}{ not a brace {\";\n"   # 7
        "  char c = '}';\n"                            # 8
        "  if (add(1) > 2) { c = '{'; }\n"             # 9
        "  return std::string(s) + c;\n"               # 10
        "}\n"                                          # 11
        "int h() { return 1'000'000; }\n"              # 12
    )
    assert spans(src) == [("g", 2, 2), ("f", 3, 11), ("h", 12, 12)]


def test_scanner_ignores_braces_in_comments_and_raw_strings():
    src = (
        "// a comment { with a brace\n"                       # 1
        "/* a block comment }\n"                              # 2
        "   over two lines { */\n"                            # 3
        "void f() {\n"                                        # 4
        "  // } not the end\n"                                # 5
        "  auto r = R\"x(raw } \" { string)x\";\n"            # 6
        "}  /* } */\n"                                        # 7
        "#define BLOCK(x) { x; }\n"                           # 8
        "void g()\n"                                          # 9
        "{\n"                                                 # 10
        "}\n"                                                 # 11
    )
    assert spans(src) == [("f", 4, 7), ("g", 9, 11)]


def test_scanner_scopes_initializers_and_constructors():
    src = (
        "namespace mmrl {\n"                                  # 1
        "enum class Kind { A, B };\n"                         # 2
        "const int table[] = {1, 2, 3};\n"                    # 3
        "struct Point : Base {\n"                             # 4
        "  Point(int a, int b) : x_{a}, y_{b} {\n"            # 5
        "    check(a);\n"                                     # 6
        "  }\n"                                               # 7
        " public:\n"                                          # 8
        "  int norm() const noexcept { return x_ + y_; }\n"   # 9
        "  bool operator==(const Point& o) const {\n"         # 10
        "    return x_ == o.x_;\n"                            # 11
        "  }\n"                                               # 12
        "  int x_{0}, y_{0};\n"                               # 13
        "};\n"                                                # 14
        "template <typename T>\n"                             # 15
        "T twice(T v) {\n"                                    # 16
        "  struct Local { int f() { return 1; } };\n"         # 17
        "  return v + v;\n"                                   # 18
        "}\n"                                                 # 19
        "}  // namespace mmrl\n"                              # 20
        "extern \"C\" {\n"                                    # 21
        "int c_api(void) { return 0; }\n"                     # 22
        "}\n"                                                 # 23
        "PYBIND11_MODULE(_core, m) {\n"                       # 24
        "  m.def(\"f\", [](int a) { return a; });\n"          # 25
        "}\n"                                                 # 26
        "Tree::Tree(int n) : tree_([&] {\n"                   # 27
        "    return build(n);\n"                              # 28
        "  }()) {}\n"                                         # 29
    )
    assert spans(src) == [("Point", 5, 7), ("norm", 9, 9), ("operator==", 10, 12), ("twice", 15, 19),
                          ("c_api", 22, 22), ("PYBIND11_MODULE", 24, 26), ("Tree::Tree", 27, 29)]


def test_python_functions_count_nested_ones_on_their_own():
    src = (
        "import functools\n"              # 1
        "@functools.lru_cache()\n"        # 2
        "def outer(a):\n"                 # 3
        "    def inner(b):\n"             # 4
        "        return b\n"              # 5
        "    return inner(a)\n"           # 6
        "class C:\n"                      # 7
        "    async def m(self):\n"        # 8
        "        pass\n"                  # 9
    )
    assert [(f.name, f.first, f.last, f.comment_from) for f in python_functions(src)] == [
        ("outer", 3, 6, -1), ("inner", 4, 5, 1), ("m", 8, 9, 5)]


def _long_function(lang: str, comment: Optional[str], gap: int = 0, lines: int = 81) -> str:
    """A function of `lines` lines with an optional comment `gap` lines above its definition."""
    head = [] if comment is None else [comment] + [""] * gap
    if lang == "py":
        return "\n".join(["x = 1"] + head + ["def f():"] + ["    x = 1"] * (lines - 2) + ["    return x", ""])
    return "\n".join(["int x = 1;"] + head + ["int f() {"] + ["  x += 1;"] * (lines - 2) + ["}", ""])


@pytest.mark.parametrize("lang", ["py", "cpp"])
def test_long_comment_exempts_only_with_a_reason_and_close_above(lang):
    mark = "#" if lang == "py" else "//"

    def found(src):
        comments = python_comments(src) if lang == "py" else cpp_comments(src)
        functions = python_functions(src) if lang == "py" else cpp_functions(src)
        return offenders("m." + lang, src, comments, functions)

    assert found(_long_function(lang, None, lines=80)) == []
    assert found(_long_function(lang, None)) == [
        f"m.{lang}:2: function f of 81 lines (> 80, no `long:` comment above it)"]
    assert found(_long_function(lang, f"{mark} long: one table of cases, clearer in one place")) == []
    assert found(_long_function(lang, f"{mark} long: reason", gap=2)) == []
    assert len(found(_long_function(lang, f"{mark} long: reason", gap=3))) == 1  # 4 lines above: too far
    assert len(found(_long_function(lang, f"{mark} long:"))) == 1  # no reason
    assert len(found(_long_function(lang, f"x = '{mark} long: in a string'" if lang == "py"
                                    else f"const char* s = \"{mark} long: in a string\";"))) == 1


@pytest.mark.parametrize("lang", ["py", "cpp"])
def test_size_comment_exempts_a_module_only_in_its_first_40_lines(lang):
    mark = "#" if lang == "py" else "//"
    filler = ("x = 1" if lang == "py" else "int x = 1;")

    def found(lines):
        src = "\n".join(lines) + "\n"
        comments = python_comments(src) if lang == "py" else cpp_comments(src)
        return offenders("m." + lang, src, comments, [])

    assert found([filler] * 500) == []
    assert found([filler] * 501) == [f"m.{lang}:1: module of 501 lines (> 500, no `size:` comment in its first 40 lines)"]
    assert found([filler] * 39 + [f"{mark} size: the generated tables"] + [filler] * 461) == []
    assert len(found([filler] * 40 + [f"{mark} size: the generated tables"] + [filler] * 460)) == 1
    assert len(found([f"{mark} size:"] + [filler] * 500)) == 1
