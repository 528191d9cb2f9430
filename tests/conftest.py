"""Shared test fixtures: where the real motion capture lives, and how to skip without it."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_WALKS = Path(os.environ.get("INSTRUMENT_WALKS", REPO.parent / "shared" / "data" / "bandai-walk"))
sys.path.insert(0, str(Path(__file__).parent))


def walk_files() -> list[Path]:
    return sorted(SHARED_WALKS.glob("*.bvh")) if SHARED_WALKS.is_dir() else []


needs_walks = pytest.mark.skipif(not walk_files(), reason=f"real walks not found in {SHARED_WALKS}")


@pytest.fixture(scope="session")
def real_walks() -> list[Path]:
    files = walk_files()
    if not files:
        pytest.skip(f"real walks not found in {SHARED_WALKS}")
    return files
