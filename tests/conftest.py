"""Shared fixtures: the real recordings of ../shared/realdata.

On a user's clone the folder is absent and the tests that need it skip with the reason; in CI
(environment variable CI=true) they fail instead, so the published-number checks always run there.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


def _in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


@pytest.fixture(scope="session")
def realdata() -> Path:
    """../shared/realdata next to the repository: skip when absent, fail when absent in CI."""
    if not REALDATA.is_dir():
        msg = f"real recordings not present at {REALDATA} (they ship beside the repository in CI)"
        if _in_ci():
            pytest.fail(f"CI=true but {msg}")
        pytest.skip(msg)
    return REALDATA
