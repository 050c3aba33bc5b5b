"""Shared code of the benchmarks in benchmarks/, and the updater of the tables in README and docs/.

    python -m benchmarks.common --update-docs    # copy every results tables.md section into its block (make docs)
    python -m benchmarks.common --check-docs     # exit 1 if a block differs from its source (make docs-check)

Data sets as the benchmarks feed them (``Part``: what the estimator is fed and the truth
``gait_estimator.analysis.evaluate.evaluate`` compares with; ``Dataset``: parts and a kernel
library), the bundled recordings (Multispeed, LG_2_Ramp), per-part counts (``part_stats``) pooled
into metrics (``pool``), rate variants of a recording, and Markdown table helpers.

Generated blocks: a page holds ``<!-- BEGIN name -->`` ... ``<!-- END name -->``. ``TOPIC`` alone
takes the whole of ``benchmarks/results/TOPIC/tables.md``; ``TOPIC#PREFIX`` takes the body of its
first heading (any level) whose text is PREFIX or starts with PREFIX followed by a
non-alphanumeric character, up to the next heading of the same or a higher level. A block whose
tables.md does not exist is left as it is and reported as pending; a missing section is an error.

Not a module of the package: the scripts import it from their own directory.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gait_estimator.analysis.evaluate import PredictionTable, circular_error, evaluate, settle_time, time_in_run
from gait_estimator.analysis.labels import duration_labels, merge_steady, read_label_ranges, with_ranges
from gait_estimator.analysis.strides import HeelStrikes, heel_strikes, nearest_index, resample_uniform
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.estimator import EstimateTrace
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.core.strides import DetectionOptions, stride_bounds
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from synthetic import Synthetic  # noqa: E402  (test helper, after sys.path)

DET = DetectionOptions()
TABLE = REPO / "config" / "transitions.yaml"
LG2_CSV = "data/swge/recordings/LG_2_Ramp_AB_Sample.csv"
MS_CSV = "data/swge/recordings/Multispeed_Walk_AB.csv"
LG2_LABELS = REPO / "data" / "swge" / "recordings" / "LG_2_Ramp_AB_Sample.labels.csv"

ROUTE = [
    ("Slow", 6), ("Med", 6), ("Fast", 6), ("RA", 6), ("SA", 6), ("Med", 6), ("SD", 6),
    ("RD", 6), ("Slow", 6), ("SA", 6), ("Fast", 6), ("RD", 6), ("Med", 6),
]
"""Synthetic route: 78 strides, 12 mode changes, all allowed by config/transitions.yaml."""


# ---------------------------------------------------------------------------------------------
# Data sets


@dataclass
class Part:
    """One recording: what the estimator is fed, and the truth evaluate compares with."""

    name: str
    feed: Recording
    truth: Recording
    hs: HeelStrikes | None
    label_map: dict[str, tuple[str, ...]] = field(default_factory=dict)
    synthetic: Synthetic | None = None


@dataclass
class Dataset:
    key: str
    title: str
    library: KernelLibrary
    parts: list[Part]
    table: str = ""  # allowed-transitions YAML for this library ('' = none)


def data_root() -> Path:
    """The project root: the paper's data are bundled under data/swge."""
    return REPO


def multispeed(shared: Path, ab: KernelLibrary) -> Dataset:
    """Multispeed, all strides within 15 % of a kernel duration labelled (run.sh --all-strides)."""
    path = shared / "data/swge/recordings/Multispeed_Walk_AB.csv"
    rec = read_recording(path, rate_hz=ab.sample_rate_hz)
    hs = heel_strikes(rec, "right_shank", None, DET)
    bounds, _ = stride_bounds(hs.times_s, DET)
    durations = {n: ab.mode(n).stride_duration_s for n in ("Slow", "Med", "Fast")}
    ranges = merge_steady(duration_labels(bounds, durations, 0.15), steady_only=False)
    truth = with_ranges(rec, ranges)
    return Dataset("MS", "Multispeed, able_bodied kernels", ab, [Part("Multispeed", rec, truth, hs)], str(TABLE))


def lg2_uniform(shared: Path, rate_hz: float | None) -> tuple[Recording, Recording]:
    """(raw labelled LG_2_Ramp, its uniform copy at ``rate_hz`` with heel-strike flags) as
    ``gait-estimator resample --labels ... --heel-strikes right_foot`` writes it."""
    raw = read_recording(shared / "data/swge/recordings/LG_2_Ramp_AB_Sample.csv")
    raw = with_ranges(raw, read_label_ranges(LG2_LABELS))
    rate = rate_hz or raw.median_rate_hz
    uni = resample_uniform(raw, rate)
    hs = heel_strikes(raw, "right_foot", rate, DET)
    flags = np.zeros(len(uni), dtype=bool)
    flags[nearest_index(uni.time_s, hs.times_s)] = True
    uni.heel_strike = flags
    return raw, uni


def column_hs(rec: Recording) -> HeelStrikes:
    return heel_strikes(rec, "column", None, DET)


def lg2_able_bodied(shared: Path, ab: KernelLibrary) -> Dataset:
    _, uni = lg2_uniform(shared, ab.sample_rate_hz)
    part = Part("LG_2_Ramp@230", uni, uni, column_hs(uni), {"level": ("Slow", "Med", "Fast")})
    return Dataset("LG2-AB", "LG_2_Ramp, able_bodied kernels", ab, [part], str(TABLE))


# ---------------------------------------------------------------------------------------------
# Running and evaluating

DATASETS: dict[str, Dataset] = {}  # filled in main() before the worker pool forks


def prediction_table(trace: EstimateTrace, source: str) -> PredictionTable:
    return PredictionTable(trace.time_s, trace.sample, trace.mode, trace.phase, trace.ready, trace.sse,
                           list(trace.mode_names), source)


def switches(trace: EstimateTrace) -> int:
    """Changes of the reported mode between consecutive ready rows."""
    m = trace.mode[trace.ready]
    return int(np.count_nonzero(m[1:] != m[:-1]))


def part_stats(ds: Dataset, part: Part, trace: EstimateTrace, collect: Sequence[str] = ()) -> dict[str, Any]:
    """Raw counts of one part (pooled over parts by ``pool``)."""
    pred = prediction_table(trace, part.name)
    ev = evaluate(pred, part.truth, part.hs, part.label_map, DET)
    m, al = ev.metrics, ev.aligned
    evald, correct = al.evaluated, al.correct & al.evaluated
    err = circular_error(al.phase, np.nan_to_num(al.phase_true))
    has_phase = evald & np.isfinite(al.phase_true)
    good = has_phase & correct
    held = trace.held & evald
    st = m["steady"]
    out: dict[str, Any] = {
        "evaluated": int(evald.sum()),
        "correct": int(correct.sum()),
        "steady": st["samples"],
        "steady_correct": round((st["accuracy"] or 0.0) * st["samples"]),
        "ph_sum": float(err[good].sum()),
        "ph_n": int(good.sum()),
        "ph_max": float(err[good].max()) if good.any() else 0.0,
        "ph_all_sum": float(err[has_phase].sum()),
        "ph_all_n": int(has_phase.sum()),
        "held": int(held.sum()),
        "nonheld_correct": int((correct & ~trace.held).sum()),
        "delays": [e["delay_s"] for e in m["transitions"]["events"] if e["delay_s"] is not None],
        "transitions": m["transitions"]["count"],
        "missed": m["transitions"]["missed"],
        "switches": switches(trace),
        "duration_s": float(trace.time_s[-1] - trace.time_s[0]),
        "per_mode": {str(n): [int((correct & (al.truth == n)).sum()), int((evald & (al.truth == n)).sum())]
                     for n in dict.fromkeys(al.truth[evald].tolist())},
    }
    if "steady_modes" in collect:
        steady = evald & (time_in_run(al.time_s, al.truth) >= settle_time(pred))
        out["per_mode_steady"] = {n: [int((correct & steady & (al.truth == n)).sum()), int((steady & (al.truth == n)).sum())]
                                  for n in dict.fromkeys(al.truth[evald].tolist())}
    return out


def pool(stats: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Combine part stats into metrics (fractions; delays in s)."""

    def total(key: str) -> float:
        return sum(s[key] for s in stats)

    def ratio(a: float, b: float) -> float | None:
        return a / b if b else None

    delays = [d for s in stats for d in s["delays"]]
    ev = total("evaluated")
    out: dict[str, Any] = {
        "evaluated": int(ev),
        "accuracy": ratio(total("correct"), ev),
        "steady_accuracy": ratio(total("steady_correct"), total("steady")),
        "phase_error_mean": ratio(total("ph_sum"), total("ph_n")),
        "phase_error_max": max(s["ph_max"] for s in stats),
        "phase_error_all_mean": ratio(total("ph_all_sum"), total("ph_all_n")),
        "held_fraction": ratio(total("held"), ev),
        "nonheld_accuracy": ratio(total("nonheld_correct"), ev - total("held")),
        "transitions": int(total("transitions")),
        "missed": int(total("missed")),
        "mean_delay_s": float(np.mean(delays)) if delays else None,
        "median_delay_s": float(np.median(delays)) if delays else None,
        "max_delay_s": float(np.max(delays)) if delays else None,
        "switches": int(total("switches")),
        "switches_per_min": 60.0 * total("switches") / total("duration_s"),
        "per_mode_accuracy": {},
    }
    modes = list(dict.fromkeys(n for s in stats for n in s["per_mode"]))
    for n in modes:
        c = sum(s["per_mode"].get(n, [0, 0])[0] for s in stats)
        e = sum(s["per_mode"].get(n, [0, 0])[1] for s in stats)
        out["per_mode_accuracy"][n] = ratio(c, e)
    return out


# ---------------------------------------------------------------------------------------------
# Rate invariance: one recording at other rates / with jitter, processed with and without --resample

def relabel(part: Part, rec: Recording) -> Part:
    """``part`` with the estimator fed ``rec`` (other sampling of the same motion); truth labels
    at ``rec``'s times from the original truth (nearest sample), heel strikes unchanged."""
    labels = None
    if part.truth.labels is not None:
        labels = part.truth.labels[nearest_index(part.truth.time_s, rec.time_s)]
    truth = Recording(time_s=rec.time_s, angles_deg=rec.angles_deg, labels=labels, source=rec.source)
    return Part(rec.source, rec, truth, part.hs, part.label_map)


def rate_variants(part: Part, rate_hz: float, seed: int = 7) -> dict[str, Recording]:
    """The part's uniform recording resampled (cubic spline through its samples: a sensor at
    another rate samples the same continuous motion) to 100/200/500 Hz, sampled at the nominal
    times +-2 ms (jitter, correct stamps), and the original samples with stamps +-2 ms off."""
    from scipy.interpolate import CubicSpline

    rec = part.feed
    t0, t1 = float(rec.time_s[0]), float(rec.time_s[-1])
    spline = CubicSpline(rec.time_s, rec.angles_deg, axis=0)
    rng = np.random.default_rng(seed)

    def make(t: np.ndarray, name: str, angles: np.ndarray | None = None) -> Recording:
        a = spline(t) if angles is None else angles
        return Recording(time_s=t, angles_deg=a, source=f"{part.name} {name}")

    out = {f"{rate_hz:g} Hz (original)": rec}
    for hz in (100.0, 200.0, 500.0):
        out[f"{hz:g} Hz"] = make(t0 + np.arange(math.floor((t1 - t0) * hz) + 1) / hz, f"{hz:g} Hz")
    jit = rng.uniform(-0.002, 0.002, len(rec))
    jit[0] = 0.0  # keep the first stamp: the resampling grid then coincides with the original samples
    jittered = rec.time_s + jit
    out[f"{rate_hz:g} Hz, sampled ±2 ms off the grid"] = make(jittered, "jitter")
    out[f"{rate_hz:g} Hz, stamps ±2 ms wrong"] = make(jittered, "stamp noise", rec.angles_deg)
    return out


# ---------------------------------------------------------------------------------------------
# Output: Markdown tables and figures


def pct(v: float | None, digits: int = 1) -> str:
    return "–" if v is None else f"{100 * v:.{digits}f} %"


def sec(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f} s"


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def machine() -> dict[str, Any]:
    """Where the numbers were measured."""
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__}


def train_lg2(shared: Path) -> KernelLibrary:
    """level/RA/RD kernels trained on LG_2_Ramp as benchmarks/accuracy.py trains them
    (``gait-estimator train LG2 --labels data/swge/recordings/LG_2_Ramp_AB_Sample.labels.csv --heel-strikes right_foot``:
    raw stamps, the library at the recording's median rate)."""
    raw, _ = lg2_uniform(shared, None)
    return train_library([raw], "lg2", TrainOptions(heel_strikes="right_foot")).library


# ---------------------------------------------------------------------------------------------
# Generated blocks in README.md and docs/ (make docs, make docs-check)

RESULTS = REPO / "benchmarks" / "results"
BLOCK = re.compile(r"^<!-- BEGIN (?P<name>[\w./-]+(?:#[^>]*?)?) -->\n(?P<body>.*?)^<!-- END (?P=name) -->$", re.M | re.S)
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$")


def pages(root: Path = REPO) -> list[Path]:
    """README.md and every Markdown page under docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def source_path(name: str, results: Path = RESULTS) -> Path:
    return results / name.split("#", 1)[0] / "tables.md"


def section(text: str, prefix: str) -> str | None:
    """Body of the first heading whose text starts with ``prefix`` (see module docstring)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        m = HEADING.match(line)
        if not m or not m.group(2).startswith(prefix):
            continue
        rest = m.group(2)[len(prefix):]
        if rest and rest[0].isalnum():
            continue
        level = len(m.group(1))
        end = next((j for j in range(i + 1, len(lines))
                    if (h := HEADING.match(lines[j])) and len(h.group(1)) <= level), len(lines))
        return "\n".join(lines[i + 1:end]).strip()
    return None


def generated(name: str, results: Path = RESULTS) -> str | None:
    """The text a block should hold, or None when its source does not exist yet (pending)."""
    path = source_path(name, results)
    if not path.is_file():
        return None
    text = path.read_text(encoding="utf-8")
    if "#" not in name:
        return text.strip()
    body = section(text, name.split("#", 1)[1])
    if body is None:
        raise SystemExit(f"{path}: no heading starting with {name.split('#', 1)[1]!r} (block {name})")
    return body


def update(page: Path, results: Path = RESULTS) -> tuple[str, list[str], list[str]]:
    """(new text, names of blocks that changed, names of pending blocks) for one page."""
    changed: list[str] = []
    pending: list[str] = []

    def splice(m: re.Match[str]) -> str:
        name = m.group("name")
        new = generated(name, results)
        if new is None:
            pending.append(name)
            return m.group(0)
        if m.group("body").strip() != new:
            changed.append(name)
        return f"<!-- BEGIN {name} -->\n{new}\n<!-- END {name} -->"

    text = page.read_text(encoding="utf-8")
    if len(re.findall(r"^<!-- BEGIN ", text, re.M)) != len(BLOCK.findall(text)):
        raise SystemExit(f"{page}: a <!-- BEGIN name --> without its <!-- END name --> (or nested blocks)")
    return BLOCK.sub(splice, text), changed, pending


def update_docs(check: bool = False, root: Path = REPO) -> int:
    """Rewrite (or with ``check`` only compare) every generated block; 1 if ``check`` finds one stale."""
    stale = []
    for page in pages(root):
        new_text, changed, pending = update(page)
        rel = page.relative_to(root)
        for name in pending:
            print(f"{rel}: {name}: pending ({source_path(name).relative_to(REPO)} does not exist yet)")
        for name in changed:
            print(f"{rel}: {name}: {'out of date' if check else 'updated'}")
        if changed and not check:
            page.write_text(new_text, encoding="utf-8")
        stale += [f"{rel}: {n}" for n in changed]
    if check and stale:
        print("generated blocks are out of date; run: make docs", file=sys.stderr)
        return 1
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Copy the tables of benchmarks/results/*/tables.md into README.md and docs/.")
    group = ap.add_mutually_exclusive_group(required=True)
    group.add_argument("--update-docs", action="store_true", help="rewrite the generated blocks (make docs)")
    group.add_argument("--check-docs", action="store_true", help="change nothing; exit 1 if a block is out of date")
    args = ap.parse_args(argv)
    from benchmarks import samples  # the sample command output docs/ shows: run again now

    if args.check_docs and samples.stale():
        print(f"{samples.OUT.relative_to(REPO)}: the commands print something else now; run: make docs", file=sys.stderr)
        return 1
    if args.update_docs:
        print(f"wrote {samples.write().relative_to(REPO)}")
    return update_docs(check=args.check_docs)


if __name__ == "__main__":
    sys.exit(main())
