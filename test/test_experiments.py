"""The scripts under experiments/ that parse options answer --help (exit 0, a usage line)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"
WITH_OPTIONS = sorted(p.name for p in EXPERIMENTS.glob("*.py") if "import argparse" in p.read_text(encoding="utf-8"))


def test_scripts_with_options_are_found() -> None:
    assert "cross_session.py" in WITH_OPTIONS and len(WITH_OPTIONS) >= 5


@pytest.mark.parametrize("script", WITH_OPTIONS)
def test_script_prints_help(script: str) -> None:
    """cross_session.py once crashed here: a setting name with '%' in its option help."""
    run = subprocess.run([sys.executable, str(EXPERIMENTS / script), "--help"], capture_output=True, text=True,
                         timeout=120, cwd=EXPERIMENTS.parent)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.startswith("usage:")
