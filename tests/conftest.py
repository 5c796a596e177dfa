"""Shared fixtures: the real recordings of ../shared/realdata (skipped with a reason if absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


@pytest.fixture(scope="session")
def realdata() -> Path:
    """../shared/realdata next to the repository; tests that need it skip when it is absent."""
    if not REALDATA.is_dir():
        pytest.skip(f"real recordings not present at {REALDATA} (they ship beside the repository in CI)")
    return REALDATA
