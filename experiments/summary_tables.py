#!/usr/bin/env python3
"""Tables of the measured results that README.md and docs/ quote (see experiments/update_docs.py).

    python experiments/summary_tables.py          # after sh experiments/run.sh (and the benches)

Writes two files:

* ``experiments/results/evaluation/tables.md``: agreement with the reference C++ output (runs
  ``gait-estimator process`` on Multispeed samples 4000..6999 and compares), and the training and
  accuracy tables of ``sh experiments/run.sh`` (read from its ``metrics.json`` files and kernels);
* ``experiments/results/headline/tables.md``: the README's headline table. Its accuracy rows come
  from the same files; its performance rows from the JSON reports of
  ``gait-estimator bench --json`` (``--bench``, default experiments/results/matcher/bench.json) and
  ``gait-estimator bench-node --json`` (``--bench-node``, default
  experiments/results/node/bench_node.json). A performance row whose report does not exist is kept
  as it is in the current headline file (with the command and machine it names), so older
  measurements are carried until someone reruns the benchmark.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results"
MULTISPEED = "data/swge/recordings/Multispeed_Walk_AB.csv"
REFERENCE = "data/swge/reference_output/trick_multispeed_4000_7000.csv"
MODE_IDS = {"Slow": 1, "Med": 2, "Fast": 3, "RA": 4, "RD": 5, "SA": 6, "SD": 7}


def pct(x: float, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f} %"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def metrics(name: str) -> dict[str, Any]:
    path = RESULTS / name / "metrics.json"
    if not path.is_file():
        sys.exit(f"{path}: missing; run sh experiments/run.sh first")
    return json.loads(path.read_text(encoding="utf-8"))


def per_mode(m: dict[str, Any], key: str, digits: int = 1) -> str:
    return ", ".join(f"{mode} {100 * v[key]:.{digits}f}" for mode, v in m["per_mode"].items())


# ---------------------------------------------------------------------------------------------
# agreement with the reference implementation


def reference_agreement() -> dict[str, Any]:
    """Run the README's command and compare with the reference C++ output, sample by sample."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "pred.csv"
        cmd = [sys.executable, "-m", "gait_estimator.cli", "process", MULTISPEED, "--kernels", "able_bodied",
               "--start", "4000", "--stop", "7000", "--preset", "paper", "--out", str(out), "--quiet"]
        subprocess.run(cmd, cwd=ROOT, check=True)
        pred = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    ref = np.loadtxt(ROOT / REFERENCE, delimiter=",", skiprows=1, usecols=(0, 1))
    lengths = {m["name"]: m["length"] for m in yaml.safe_load((ROOT / "config/kernels/able_bodied.yaml").read_text())["modes"]}
    mode_ok = np.array([MODE_IDS[str(m)] for m in pred["mode"]]) == ref[:, 1].astype(int)
    d = np.abs(pred["phase"].astype(float) - ref[:, 0])
    columns = np.minimum(d, 1.0 - d) * np.array([lengths[str(m)] for m in pred["mode"]])  # reference: 1.0 for our 0.0
    return {"samples": len(ref), "mode": int(mode_ok.sum()), "phase_exact": int((columns < 1e-3).sum()),
            "phase_one_column": int((columns <= 1.0 + 1e-4).sum())}


# ---------------------------------------------------------------------------------------------
# evaluation/tables.md


def transitions(m: dict[str, Any]) -> str:
    """Detected/total label changes and each delay (negative: switched inside an unlabelled gap)."""
    t = m["transitions"]
    delays = [e["delay_s"] for e in t["events"] if e.get("delay_s") is not None]
    text = f"{t['detected']}/{t['count']}"
    if delays:
        text += f": {', '.join(f'{d:.2f}' for d in delays)} s (mean {t['mean_delay_s']:.2f} s)"
    return text


def phase_cell(m: dict[str, Any]) -> str:
    text = (f"{pct(m['phase_error_mean'], 2)} ± {pct(m['phase_error_std'], 2)} (max {pct(m['phase_error_max'])}); "
            f"{per_mode(m, 'phase_error_mean', 2)} %; steady {pct(m['steady']['phase_error_mean'], 2)}")
    if m["phase_error_all_max"] > m["phase_error_max"]:
        text += f"; all rows max {pct(m['phase_error_all_max'])}"
    return text


def accuracy_row(label: str, m: dict[str, Any]) -> list[str]:
    modes = f" ({per_mode(m, 'accuracy')} %)" if len(m["per_mode"]) > 1 else ""
    return [label, f"{m['samples']['evaluated']:,}", pct(m["accuracy"]) + modes,
            f"{pct(m['steady']['accuracy'])} of {m['steady']['samples']:,}", phase_cell(m), transitions(m)]


ACCURACY_HEADER = ["evaluated samples", "accuracy (per mode)", "steady rows", "phase error mean ± std (max); per mode",
                   "label changes: delays"]


def evaluation_tables(ref: dict[str, Any]) -> str:
    n = ref["samples"]
    parts = [
        "Generated by `python experiments/summary_tables.py` from the outputs of `sh experiments/run.sh` "
        "(deterministic: the same on any machine with the same code and data).",
        "### Reference agreement\n\n" + table(
            ["comparison", "samples", "same mode", "same phase (exactly)", "phase within one kernel column"],
            [["`gait-estimator process " + MULTISPEED + " --start 4000 --stop 7000 --preset paper` vs `" + REFERENCE + "`",
              f"{n:,}", f"{ref['mode']:,}/{n:,}", f"{ref['phase_exact']:,}/{n:,}", f"{ref['phase_one_column']:,}/{n:,}"]]),
    ]

    lib = yaml.safe_load((RESULTS / "lg2_kernels.yaml").read_text(encoding="utf-8"))
    rows = [[m["name"], str(m["info"]["strides"]),
             f"{m['info']['duration_mean_s']:.3f} ± {m['info']['duration_std_s']:.3f}", str(m["length"])]
            for m in lib["modes"]]
    found = sum(m["info"]["strides_found"] for m in lib["modes"])
    rejected = sum(len(m["info"]["rejected"]) for m in lib["modes"])
    parts.append(
        "### LG_2_Ramp kernels\n\n" + table(["mode", "strides", "duration mean ± std (s)", "N_m"], rows)
        + f"\n\nRejected as outliers: {rejected} of {found} strides; library rate {lib['modes'][0]['sample_rate_hz']:.3f} Hz."
    )
    parts.append("### LG_2_Ramp accuracy\n\n" + table(
        ["kernels", *ACCURACY_HEADER],
        [accuracy_row("trained on this recording (**in-sample**)", metrics("lg2_insample")),
         accuracy_row("bundled able_bodied (another session; level = Slow, Med or Fast)", metrics("lg2_able_bodied"))]))
    parts.append("### Multispeed accuracy\n\n" + table(
        ["Multispeed", *ACCURACY_HEADER],
        [accuracy_row("able_bodied kernels, steady strides (the comparable case)", metrics("multispeed")),
         accuracy_row("able_bodied kernels, every stride within 15 % (`--all-strides`, speed changes included)",
                      metrics("multispeed_all")),
         accuracy_row("personal kernels: trained on the first half of each steady run, tested on the second",
                      metrics("multispeed_split"))]))
    return "\n\n".join(parts) + "\n"


# ---------------------------------------------------------------------------------------------
# headline/tables.md

HEADER = ["measure", "result", "paper", "measured with"]
STEP_ROW = "matcher time per sample (median), 7 / 700 modes"
NODE_ROW = "node latency at 230 Hz, input → `estimate` (p50 / p99); highest input rate without drops"


def machine(m: dict[str, Any]) -> str:
    return f"{m.get('processor') or m.get('machine', '?')}, {m.get('cpus', '?')} CPUs, Python {m.get('python', '?')}"


def carried_rows(path: Path) -> dict[str, list[str]]:
    """Rows of the current headline table, by measure (for rows whose report is missing)."""
    if not path.is_file():
        return {}
    rows = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []
        if len(cells) == len(HEADER) and cells[0] not in (HEADER[0], "---"):
            rows[cells[0]] = cells
    return rows


def missing(path: Path, command: str) -> list[str]:
    sys.exit(f"{path}: missing and no earlier headline row to carry; run {command} --json {path}")


def step_row(path: Path, carried: dict[str, list[str]]) -> list[str]:
    if not path.is_file():
        return carried.get(STEP_ROW) or missing(path, "gait-estimator bench --modes 7,700")
    report = json.loads(path.read_text(encoding="utf-8"))
    rows = {(r["modes"], r["impl"], r.get("preset", "paper")): r["step_us_median"] for r in report["results"]}
    impl = next(i for _, i, _ in rows if i.startswith("incremental ("))
    med = {m: v for (m, i, p), v in rows.items() if i == impl and p == "paper"}
    lo, hi = min(med), max(med)
    est = {p: rows.get((lo, impl.replace("incremental", "estimator"), p)) for p in ("paper", "default")}
    extra = (f"; whole `Estimator.update` at {lo} modes: {est['default']:,.1f} µs default preset, "
             f"{est['paper']:,.1f} µs paper preset" if all(est.values()) else "")
    return [STEP_ROW if (lo, hi) == (7, 700) else f"matcher time per sample (median), {lo} / {hi} modes",
            f"{med[lo]:,.1f} µs / {med[hi]:,.0f} µs, paper preset, {impl[len('incremental '):].strip('()')} step{extra} "
            "(a sample arrives every 4,348 µs at 230 Hz)",
            "2.91 µs, 7 modes (C++, Apple M3 Pro)",
            f"`gait-estimator bench --modes 7,700 --json` on {machine(report['machine'])}"]


def new_wearer_rows(path: Path) -> list[list[str]]:
    """Rows from experiments/cross_session.py's summary.json (default preset vs paper)."""
    if not path.is_file():
        sys.exit(f"{path}: missing; run python experiments/cross_session.py first")
    res = json.loads(path.read_text(encoding="utf-8"))["results"]
    cmd = "`python experiments/cross_session.py` (deterministic)"
    rows = []
    for key, what in (("SYN-NEW", "synthetic new wearers (offsets ±8°, amplitude ±15 %, cadence ±12 %, 100–500 Hz), 7 modes"),
                      ("SYN-NEW-L", "the same, Slow/Med/Fast scored as one level-walking class"),
                      ("LG2-AB", "LG_2_Ramp at its own stamps, bundled kernels of another session")):
        if key not in res:
            continue
        d, p = res[key]["default"], res[key]["paper"]
        rows.append([f"new wearer: {what}",
                     f"accuracy {pct(d['accuracy'])} (steady {pct(d['steady_accuracy'])}), phase error "
                     f"{pct(d['phase_error_mean'], 2)}; paper preset {pct(p['accuracy'])}, {pct(p['phase_error_mean'], 2)}",
                     "—", cmd])
    return rows


def node_row(path: Path, carried: dict[str, list[str]]) -> list[str]:
    if not path.is_file():
        return carried.get(NODE_ROW) or missing(path, "gait-estimator bench-node")
    report = json.loads(path.read_text(encoding="utf-8"))
    lat, tp = report["latency"], report["throughput"]
    result = f"{lat['p50_ms']:.2f} / {lat['p99_ms']:.2f} ms"
    if "dds_p50_ms" in lat:  # since bench-node also measures to the subscriber's DDS reader
        result = (f"{lat['dds_p50_ms']:.2f} / {lat['dds_p99_ms']:.2f} ms at the subscriber's DDS reader, "
                  f"{result} in its rclpy callback")
    load = report.get("load_average_before")
    return [NODE_ROW, f"{result}; {tp['max_sustained_rate_hz']:,.0f} Hz", "—",
            f"`gait-estimator bench-node --json` on {machine(report['machine'])}"
            + (f", load average {load[0]:.2f} before the run" if load else "")]


def headline(ref: dict[str, Any], bench: Path, bench_node: Path, current: Path, cross: Path) -> str:
    ms, ms_all, lg2 = metrics("multispeed"), metrics("multispeed_all"), metrics("lg2_able_bodied")
    carried = carried_rows(current)
    run = "`sh experiments/run.sh` (deterministic)"
    rows = [
        ["agreement with the reference C++ implementation (Multispeed samples 4000–6999)",
         f"mode {ref['mode']:,}/{ref['samples']:,}; phase {ref['phase_exact']:,}/{ref['samples']:,} exactly, "
         f"{ref['phase_one_column']:,}/{ref['samples']:,} within one kernel column", "—",
         "`python experiments/summary_tables.py`; `make test` checks it"],
        ["mode accuracy, Multispeed treadmill walk, steady strides (3 speeds); possibly in-sample",
         f"{pct(ms['accuracy'])} of {ms['samples']['evaluated']:,} samples", "99.1 % steady state, 7 modes", run],
        ["mode accuracy, Multispeed, every stride (speed changes included); possibly in-sample",
         f"{pct(ms_all['accuracy'])} of {ms_all['samples']['evaluated']:,}; steady rows {pct(ms_all['steady']['accuracy'])}",
         "—", run],
        ["mode accuracy, LG_2_Ramp level/ramp walk (230 Hz copy), kernels from another session",
         f"{pct(lg2['accuracy'])} of {lg2['samples']['evaluated']:,}; steady rows {pct(lg2['steady']['accuracy'])}", "—", run],
        ["phase error, Multispeed steady strides (% of a stride); possibly in-sample",
         f"{pct(ms['phase_error_mean'], 2)} mean, {pct(ms['phase_error_max'])} max", "≤ 1.8 % level walking, < 4 % every mode",
         run],
        *new_wearer_rows(cross),
        step_row(bench, carried),
        node_row(bench_node, carried),
    ]
    return table(HEADER, rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bench", type=Path, default=RESULTS / "matcher" / "bench.json",
                    help="JSON of gait-estimator bench --modes 7,...,700 (default %(default)s)")
    ap.add_argument("--bench-node", type=Path, default=RESULTS / "node" / "bench_node.json",
                    help="JSON of gait-estimator bench-node (default %(default)s)")
    ap.add_argument("--cross-session", type=Path, default=RESULTS / "cross_session" / "summary.json",
                    help="summary.json of experiments/cross_session.py (default %(default)s)")
    args = ap.parse_args(argv)
    ref = reference_agreement()
    out = RESULTS / "evaluation" / "tables.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(evaluation_tables(ref), encoding="utf-8")
    head = RESULTS / "headline" / "tables.md"
    head.parent.mkdir(parents=True, exist_ok=True)
    text = headline(ref, args.bench, args.bench_node, head, args.cross_session)
    head.write_text(text, encoding="utf-8")
    print(f"wrote {out.relative_to(ROOT)} and {head.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
