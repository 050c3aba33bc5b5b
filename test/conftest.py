"""Test fixtures: the project's bundled data (data/swge) and kernel libraries."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SWGE = REPO / "data" / "swge"


@pytest.fixture(scope="session")
def swge() -> Path:
    """The paper's data bundled with the project (data/swge)."""
    assert (SWGE / "recordings").is_dir(), f"bundled data missing: {SWGE}"
    return SWGE


@pytest.fixture(scope="session")
def multispeed_csv(swge: Path) -> Path:
    return swge / "recordings" / "Multispeed_Walk_AB.csv"


@pytest.fixture(scope="session")
def able_bodied():
    from gait_estimator import load_library

    return load_library("able_bodied")
