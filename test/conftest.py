"""Shared test fixtures: the ../shared data beside the checkout, bundled libraries."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("GAIT_ESTIMATOR_SHARED", REPO.parent / "shared")).resolve()
SWGE = SHARED / "data" / "swge"


@pytest.fixture(scope="session")
def swge() -> Path:
    """The paper's data directory (../shared/data/swge); fails loudly when it is missing."""
    if not (SWGE / "recordings").is_dir():
        pytest.fail(f"shared data not found at {SWGE}: clone the project with ../shared beside it "
                    "or set GAIT_ESTIMATOR_SHARED")
    return SWGE


@pytest.fixture(scope="session")
def multispeed_csv(swge: Path) -> Path:
    return swge / "recordings" / "Multispeed_Walk_AB.csv"


@pytest.fixture(scope="session")
def able_bodied():
    from gait_estimator import load_library

    return load_library("able_bodied")
