"""Shared fixtures. Real-data tests read ../shared/data/bandai-namco-2 beside the checkout;
they fail (never skip) when the CI environment variable is set and the data is missing."""
import os
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-namco-2"


def require_shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        if os.environ.get("CI"):
            pytest.fail(f"shared data missing at {SHARED_DATA}; CI must provide ../shared")
        pytest.skip(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def shared_data() -> Path:
    return require_shared_data()


@pytest.fixture(scope="session")
def shared_db(shared_data):
    import mmrl

    return mmrl.Database.from_bvh(shared_data)
