#!/usr/bin/env python3
"""Matcher and estimator timing tables from the JSON reports of ``gait-estimator bench``.

    python benchmarks/performance.py          # tables only (part of `make docs`)
    python benchmarks/performance.py --run    # first rerun bench.json (both cores, about 10 min)
    python benchmarks/performance.py --offline TREE  # first rerun offline.json (about 1 min)

Reads, in benchmarks/results/performance/ (a missing report leaves its section out):

* ``bench.json``: ``gait-estimator bench --modes 7,70,700 --drift-steps 1000000 --json ...`` on a
  quiet machine (both cores);
* ``bench_one_core.json``: ``taskset -c 0 gait-estimator bench --modes 7,70,700 --json ...``;
* ``offline.json``: ``python benchmarks/performance.py --offline TREE`` (benchmarks/offline.py:
  offline throughput against the checkout TREE of older code, and its ceiling).

Writes ``tables.md`` with the sections ``Two cores``, ``One core`` and ``Offline throughput``
(docs/performance.md).
Timings are noisy on a shared machine: rerun on a quiet one, and compare ratios within one run.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DIR = ROOT / "benchmarks" / "results" / "performance"
PERIODS_US = {230: 1e6 / 230, 1000: 1000.0}
TARGETS_US = {7: 15.0, 700: 500.0}


def load(name: str) -> dict[str, Any] | None:
    p = DIR / name
    return json.loads(p.read_text(encoding="utf-8")) if p.is_file() else None


def machine(report: dict[str, Any]) -> str:
    m = report["machine"]
    load_avg = m.get("load_average")
    date = f"{report['date']}, " if report.get("date") else ""
    return (f"{date}{m.get('processor', '?')}, {m.get('cpus_allowed', '?')} of {m.get('cpus', '?')} CPUs allowed, "
            f"Python {m.get('python', '?')}, numpy {m.get('numpy', '?')}, numba {m.get('numba') or 'not installed'}"
            + (f"; 1-min load average {load_avg[0]:.2f} at the end" if load_avg else ""))


def what(r: dict[str, Any]) -> str:
    rows = f", {r['rows']} rows" if "rows" in r else ""
    return f"{r['impl']}, {r.get('preset', 'paper')} preset{rows}"


def results_table(report: dict[str, Any]) -> str:
    lines = ["| modes M | what | median per step | p99 per step | state memory | offline throughput |",
             "|---|---|---|---|---|---|"]
    for r in report["results"]:
        if "stride-start reader" in r["impl"] or "step_us_median" not in r:  # a retired option; throughput rows
            continue
        state = f"{r['state_bytes'] / 1e6:.2f} MB" if "state_bytes" in r else "—"
        offline = f"{r['offline_samples_per_s']:,.0f} samples/s" if "offline_samples_per_s" in r else "—"
        lines.append(f"| {r['modes']} | {what(r)} | {r['step_us_median']:,.1f} µs | {r['step_us_p99']:,.1f} µs | "
                     f"{state} | {offline} |")
    return "\n".join(lines)


def compiled_medians(report: dict[str, Any]) -> dict[int, float]:
    return {r["modes"]: r["step_us_median"] for r in report["results"]
            if r["impl"] == "incremental (numba)" and r.get("preset", "paper") == "paper"}


def two_cores(report: dict[str, Any]) -> str:
    med = compiled_medians(report)
    notes = []
    for m, target in TARGETS_US.items():
        if m in med:
            notes.append(f"M = {m}: {med[m]:,.1f} µs median, target ≤ {target:,.0f} µs: "
                         + ("**met**" if med[m] <= target else "**missed**"))
    by = {(r["modes"], r["impl"], r.get("preset", "paper")): r for r in report["results"]}
    for m in sorted({k[0] for k in by}):
        np_ = by.get((m, "incremental (numpy)", "paper"))
        nb = by.get((m, "incremental (numba)", "paper"))
        if np_ and nb:
            notes.append(f"M = {m}: the numpy fallback takes {np_['step_us_median'] / nb['step_us_median']:.1f}× the "
                         "compiled step")
        est = {p: by.get((m, "estimator (numba)", p)) for p in ("paper", "default")}
        notes.extend(preset_notes(by, m))
        proc = [(p, by[(m, "process", p)]) for p in ("paper", "default") if (m, "process", p) in by]
        if proc:
            notes.append(f"M = {m}: `run_estimator` (behind `process`) in bulk: " + ", ".join(
                f"{p} preset {r['samples_per_s']:,.0f} samples/s ({r['speedup']:.1f}× sample by sample"
                + ("" if r["same_estimates"] else "; DIFFERENT ESTIMATES") + ")" for p, r in proc))
        fallback = by.get((m, "estimator (numpy)", "default"))
        if fallback and est["default"]:
            notes.append(f"M = {m}: without numba (the numpy fallback) a whole default-preset update takes "
                         f"{fallback['step_us_median']:,.1f} µs, "
                         f"{fallback['step_us_median'] / est['default']['step_us_median']:.1f}× the compiled one")
    drift = report.get("drift")
    if drift:
        notes.append(f"long run: after {drift['steps']:,} steps (M = {drift['modes']}) the running sums differ from a "
                     f"from-scratch recomputation by at most {drift['max_relative_error']:.1e} (relative; required ≤ 1e-9)")
    loads = report.get("library_load", [])
    if loads:
        notes.append(f"a {loads[0]['modes']}-mode library loads in "
                     + " and ".join(f"{r['load_s']:.3f} s from {r['format']}" for r in loads))
    return ("## Two cores\n\n"
            f"`gait-estimator bench --modes 7,70,700 --drift-steps 1000000 --json benchmarks/results/performance/bench.json` "
            f"on the {report.get('machine_note', 'quiet development machine')} ({machine(report)}).\n\n"
            + "\n".join(f"* {n}." for n in notes) + "\n\n## Two cores: every row\n\n" + results_table(report) + "\n")


def preset_notes(by: dict[tuple[int, str, str], dict[str, Any]], m: int) -> list[str]:
    """The default preset's whole ``Estimator.update`` against the paper preset's at M = m, timed
    in turn on the same samples: once calibrated and while calibrating, each row's ratios and the
    target (median and p99 at most 2x), and the state memory."""
    notes = []
    for impl, when in (("estimator (numba), calibrating", "calibrating"), ("estimator (numba)", "calibrated")):
        d, p = by.get((m, impl, "default")), by.get((m, impl, "paper"))
        if not (d and p):
            continue
        first = d["timed_from_sample"]
        ratio, p99 = d["step_us_median"] / p["step_us_median"], d["step_us_p99"] / p["step_us_p99"]
        notes.append(f"M = {m}, {when} (samples {first:,}–{first + d['steps_timed']:,}): update default "
                     f"{d['step_us_median']:,.1f} µs, paper {p['step_us_median']:,.1f} µs median ({ratio:.2f}×); p99 "
                     f"{d['step_us_p99']:,.1f} and {p['step_us_p99']:,.1f} µs ({p99:.2f}×); ≤ 2×: "
                     + ("**met**" if max(ratio, p99) <= 2.0 else "**missed**"))
    d, p = by.get((m, "estimator (numba)", "default")), by.get((m, "estimator (numba)", "paper"))
    if d and p and "state_bytes" in d and "state_bytes" in p:
        ratio = d["state_bytes"] / p["state_bytes"]
        notes.append(f"M = {m}: matcher state {d['state_bytes'] / 1e6:,.1f} MB, paper {p['state_bytes'] / 1e6:,.1f} MB "
                     f"({ratio:.1f}×); ≤ 2×: " + ("**met**" if ratio <= 2.0 else "**missed**"))
    return notes


def one_core(report: dict[str, Any]) -> str:
    med = compiled_medians(report)
    by = {(r["modes"], r["impl"], r.get("preset", "paper")): r for r in report["results"]}
    lines = []
    for m in sorted(med):
        est = by.get((m, "estimator (numba)", "default"))
        cost = est["step_us_median"] if est else med[m]
        label = "a whole default-preset `Estimator.update`" if est else "the paper preset's compiled matcher step"
        budget = "; ".join(f"at {hz:,} Hz it uses {100 * cost / per:.1f} % of the {per:,.0f} µs between samples"
                           for hz, per in PERIODS_US.items())
        lines.append(f"M = {m}: {label}, {cost:,.1f} µs median ({budget})")
        lines.extend(preset_notes(by, m))
    return ("## One core (`taskset -c 0`)\n\n"
            "`taskset -c 0 gait-estimator bench --modes 7,70,700 --json benchmarks/results/performance/bench_one_core.json` "
            f"on the {report.get('machine_note', 'quiet development machine')} ({machine(report)}), a stand-in for a "
            "Raspberry Pi-class "
            "computer.\n\n" + "\n".join(f"* {n}." for n in lines) + "\n\n## One core: every row\n\n"
            + results_table(report) + "\n")


def offline_section(report: dict[str, Any]) -> str:
    from offline import section

    return section(report)


def run_bench(note: str | None = None) -> None:
    """Rerun bench.json: ``gait-estimator bench --modes 7,70,700 --drift-steps 1000000 --json``;
    ``note`` describes the machine's state (default: quiet development machine)."""
    DIR.mkdir(parents=True, exist_ok=True)
    path = DIR / "bench.json"
    subprocess.run([sys.executable, "-m", "gait_estimator.cli", "bench", "--modes", "7,70,700", "--drift-steps", "1000000",
                    "--json", str(path)], cwd=ROOT, check=True)
    report = json.loads(path.read_text(encoding="utf-8"))
    report["date"] = datetime.datetime.now(datetime.timezone.utc).date().isoformat()
    if note:
        report["machine_note"] = note
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", action="store_true", help="rerun bench.json first (about 10 min), then the tables")
    ap.add_argument("--note", help="with --run: the machine's state, e.g. 'development machine, shared with other "
                    "jobs' (default: quiet development machine)")
    ap.add_argument("--offline", type=Path, metavar="TREE", help="rerun offline.json first, against the older "
                    "code checked out in TREE (e.g. git worktree add /tmp/old 5b851d2)")
    args = ap.parse_args(argv)
    if args.run:
        run_bench(args.note)
    if args.offline:
        from offline import run

        DIR.mkdir(parents=True, exist_ok=True)
        run(args.offline, DIR / "offline.json")
    parts = []
    for name, fn in (("bench.json", two_cores), ("bench_one_core.json", one_core), ("offline.json", offline_section)):
        report = load(name)
        if report is not None:
            parts.append(fn(report))
    if not parts:
        sys.exit(f"{DIR}: no bench reports; run the commands in this script's docstring")
    out = DIR / "tables.md"
    out.write_text("\n".join(parts), encoding="utf-8")
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
