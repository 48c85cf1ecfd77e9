"""Shared fixtures.

Tests that need the real Bandai-Namco mocap take the ``shared_data`` fixture (or call
``require_shared_data``). The data is looked up in ``$MMRL_DATA``, then in ``../shared``
beside the checkout, then in ``~/.cache/mmrl/bandai-namco-2`` (where ``mmrl data fetch
bandai-namco-2`` puts it). In the project's CI (the ``CI`` variable set by the runner) a
missing data set fails those tests; elsewhere they skip, and the run ends with one line
saying why and how to get it.
"""
import os
from pathlib import Path

import pytest

HOW_TO_GET = ("get it with `mmrl data fetch bandai-namco-2` (CC BY-NC 4.0) or point MMRL_DATA at a copy "
              "of its directory")
_CANDIDATES = [Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2",
               Path.home() / ".cache" / "mmrl" / "bandai-namco-2"]
_skipped = []


def find_shared_data():
    """The Bandai-Namco directory (with its style folders), or None."""
    env = os.environ.get("MMRL_DATA") or os.environ.get("MMRL_BANDAI_DIR")
    for candidate in ([Path(env)] if env else []) + _CANDIDATES:
        if (candidate / "normal").is_dir():
            return candidate
    return None


SHARED_DATA = find_shared_data() or _CANDIDATES[0]


def require_shared_data() -> Path:
    found = find_shared_data()
    if found is None:
        where = os.environ.get("MMRL_DATA") or _CANDIDATES[0]
        if os.environ.get("CI"):
            pytest.fail(f"the Bandai-Namco mocap is missing at {where}; CI must provide ../shared beside the "
                        f"checkout (or MMRL_DATA)")
        _skipped.append(1)
        pytest.skip(f"needs the Bandai-Namco mocap, not found at {where}; {HOW_TO_GET}")
    return found


def require_lafan1(probe: str = "") -> Path:
    """The shared LAFAN1 directory (``../shared/data/lafan1``, or ``MMRL_LAFAN1``) holding
    ``probe``; CI fails without it, elsewhere the test skips with one line."""
    env = os.environ.get("MMRL_LAFAN1")
    where = Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data" / "lafan1"
    if not (where / probe).exists() or not any(where.rglob("*.bvh")):
        if os.environ.get("CI"):
            pytest.fail(f"LAFAN1 is missing at {where}; CI must provide ../shared beside the checkout (or MMRL_LAFAN1)")
        pytest.skip(f"needs LAFAN1 (../shared/data/lafan1, or MMRL_LAFAN1), not found at {where}")
    return where


_browser_skips = []


def note_browser_skip(message: str) -> None:
    """The browser tests (tests/test_viewer_browser.py) skip outside CI when chromium,
    Playwright or viser is missing; the run ends with one line saying what to install."""
    if message not in _browser_skips:
        _browser_skips.append(message)


def pytest_terminal_summary(terminalreporter):
    for message in _browser_skips:
        terminalreporter.write_line(f"The browser tests were skipped: {message}.")
    if _skipped:
        terminalreporter.write_line(f"The tests that need the Bandai-Namco mocap were skipped: it is not here; "
                                    f"{HOW_TO_GET}.")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    return require_shared_data()


@pytest.fixture(scope="session")
def shared_db(shared_data):
    import mmrl

    return mmrl.Database.from_bvh(shared_data)
