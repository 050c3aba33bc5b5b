"""Sample command output shown in docs/, from running the commands: ``python -m benchmarks.common
--update-docs`` (make docs) writes it, ``--check-docs`` (make docs-check) reruns and compares it.

Each sample runs its commands as a user would from a clone (in a temporary directory holding a
link to ``data/``), and keeps what the page shows of the output: ``benchmarks/results/samples/
tables.md``, one section per sample, copied into the page's ``<!-- BEGIN samples#NAME -->``
block.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "benchmarks" / "results" / "samples" / "tables.md"
RAMP = "data/swge/recordings/LG_2_Ramp_AB_Sample.csv"


def _segments_elided(lines: list[str]) -> list[str]:
    """The first segment of a ``process`` summary, then '...' up to the next line that is not one."""
    start = lines.index("segments:") + 2
    end = next(i for i in range(start, len(lines)) if not lines[i].startswith("  "))
    return [*lines[:start], "      ...", *lines[end:]]


SAMPLES: dict[str, tuple[list[list[str]], int, Callable[[list[str]], list[str]]]] = {
    # name: (commands run in order, index of the one shown, what of its output is shown)
    "bags process": ([["convert", RAMP, "--out-bag", "out/ramp_bag"],
                      ["process", "out/ramp_bag", "--out-bag", "out/ramp_est"]], 1, _segments_elided),
}


def run_sample(commands: list[list[str]], shown: int, keep: Callable[[list[str]], list[str]]) -> str:
    """The shown command and what is kept of its output, as a fenced text block."""
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "data").symlink_to(REPO / "data")
        for i, args in enumerate(commands):
            proc = subprocess.run([sys.executable, "-m", "gait_estimator.cli", *args], cwd=tmp, capture_output=True,
                                  text=True, check=False)
            if proc.returncode != 0:
                raise SystemExit(f"gait-estimator {' '.join(args)}: exit {proc.returncode}: {proc.stderr.strip()}")
            if i == shown:
                text = "\n".join(keep(proc.stdout.rstrip("\n").splitlines()))
                return f"```text\n$ gait-estimator {' '.join(args)}\n{text}\n```"
    raise ValueError(f"no command {shown}")


def tables() -> str:
    return "\n\n".join(f"### {name}\n\n{run_sample(*sample)}" for name, sample in SAMPLES.items()) + "\n"


def write() -> Path:
    """Run the samples, write tables.md; its path."""
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(tables(), encoding="utf-8")
    return OUT


def stale() -> bool:
    """True when the samples' output is no longer what tables.md holds."""
    return not OUT.is_file() or OUT.read_text(encoding="utf-8") != tables()
