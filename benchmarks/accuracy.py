#!/usr/bin/env python3
"""Accuracy on the bundled recordings: the README's results table and docs/training.md's tables.

    python benchmarks/accuracy.py                # ~1 min: train, process, evaluate; then the tables
    python benchmarks/accuracy.py --tables-only  # only the tables, from the results already there

Runs the ``gait-estimator`` commands a user would (train, resample, process, label-strides,
evaluate) on data/swge/recordings, writing into benchmarks/results/accuracy/ (kernels, label
ranges, one ``evaluate --out-dir`` per case; predictions and resampled copies under ``work/``),
then ``tables.md`` there with the sections ``Results`` (README), ``Reference agreement``,
``LG_2_Ramp kernels``, ``LG_2_Ramp accuracy`` and ``Multispeed accuracy`` (docs). The accuracy
figures are deterministic: the same on any machine with the same code and data. The results table
also quotes benchmarks/cross_session.py's summary.json and the timing reports in
benchmarks/results/performance/bench.json and benchmarks/results/node/bench_node.json.
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
from common import REPO, RESULTS, md_table

from gait_estimator.analysis.labels import LabelRange, read_label_ranges, write_label_ranges

OUT = RESULTS / "accuracy"
REC = "data/swge/recordings"
LG2 = f"{REC}/LG_2_Ramp_AB_Sample.csv"
MULTISPEED = f"{REC}/Multispeed_Walk_AB.csv"
LG2_LABELS = f"{REC}/LG_2_Ramp_AB_Sample.labels.csv"
REFERENCE = "data/swge/reference_output/trick_multispeed_4000_7000.csv"
MODE_IDS = {"Slow": 1, "Med": 2, "Fast": 3, "RA": 4, "RD": 5, "SA": 6, "SD": 7}
COMMAND = "`python benchmarks/accuracy.py` (deterministic)"


# ---------------------------------------------------------------------------------------------
# Running the commands


def ge(*args: str) -> None:
    """``gait-estimator ARGS`` from the repository root (paths relative to it)."""
    print("gait-estimator " + " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "gait_estimator.cli", *args], cwd=REPO, check=True)


def split_ranges(src: Path, train: Path, test: Path) -> None:
    """Every label range split at its midpoint: first halves to ``train``, second to ``test`` (a
    1:1 split of one recording, as the paper splits its trials; strides straddling a midpoint are
    in neither half for training)."""
    ranges = read_label_ranges(src)
    mids = [0.5 * (r.start_s + r.end_s) for r in ranges]
    note = f"split of {src.relative_to(REPO)} at the midpoint of every range (benchmarks/accuracy.py)"
    write_label_ranges([LabelRange(r.start_s, m, r.mode) for r, m in zip(ranges, mids, strict=True)], train,
                       ["training half: " + note])
    write_label_ranges([LabelRange(m, r.end_s, r.mode) for r, m in zip(ranges, mids, strict=True)], test,
                       ["test half: " + note])


def run(out: Path) -> None:
    o = str(out.relative_to(REPO))
    w = f"{o}/work"
    (out / "work").mkdir(parents=True, exist_ok=True)
    hs_foot = ("--heel-strikes", "right_foot")
    hs_shank = ("--heel-strikes", "right_shank")
    # LG_2_Ramp: level/RA/RD kernels from time-range labels, evaluated in-sample on a uniform copy
    ge("train", LG2, "--labels", LG2_LABELS, *hs_foot, "--out", f"{o}/lg2_kernels.yaml")
    ge("resample", LG2, "--labels", LG2_LABELS, *hs_foot, "--out", f"{w}/lg2_uniform.csv")
    ge("process", f"{w}/lg2_uniform.csv", "--kernels", f"{o}/lg2_kernels.yaml", "--out", f"{w}/lg2_pred.csv", "--quiet")
    ge("evaluate", "--predictions", f"{w}/lg2_pred.csv", "--truth", f"{w}/lg2_uniform.csv", "--out-dir",
       f"{o}/lg2_insample", "--title", "LG_2_Ramp, kernels trained on the same recording (in-sample)")
    # LG_2_Ramp with the bundled able_bodied kernels (230 Hz copy); level = Slow, Med or Fast
    ge("resample", LG2, "--rate", "230", "--labels", LG2_LABELS, *hs_foot, "--out", f"{w}/lg2_230.csv")
    ge("process", f"{w}/lg2_230.csv", "--kernels", "able_bodied", "--out", f"{w}/lg2_able_bodied_pred.csv", "--quiet")
    ge("evaluate", "--predictions", f"{w}/lg2_able_bodied_pred.csv", "--truth", f"{w}/lg2_230.csv",
       "--label-map", "level=Slow|Med|Fast", "--out-dir", f"{o}/lg2_able_bodied",
       "--title", "LG_2_Ramp, bundled able_bodied kernels")
    # Multispeed: labels from stride durations (steady strides; then every stride within 15 %)
    modes = ("--kernels", "able_bodied", "--modes", "Slow,Med,Fast", *hs_shank)
    ge("label-strides", MULTISPEED, *modes, "--out", f"{o}/multispeed_labels.csv")
    ge("process", MULTISPEED, "--kernels", "able_bodied", "--out", f"{w}/multispeed_pred.csv", "--quiet")
    ge("evaluate", "--predictions", f"{w}/multispeed_pred.csv", "--truth", MULTISPEED, "--labels",
       f"{o}/multispeed_labels.csv", *hs_shank, "--out-dir", f"{o}/multispeed",
       "--title", "Multispeed_Walk_AB, bundled able_bodied kernels")
    ge("label-strides", MULTISPEED, *modes, "--all-strides", "--out", f"{o}/multispeed_labels_all.csv")
    ge("evaluate", "--predictions", f"{w}/multispeed_pred.csv", "--truth", MULTISPEED, "--labels",
       f"{o}/multispeed_labels_all.csv", *hs_shank, "--out-dir", f"{o}/multispeed_all",
       "--title", "Multispeed_Walk_AB, all strides labelled, able_bodied")
    # Multispeed, personal kernels: train on the first half of every steady run, test on the second
    split_ranges(out / "multispeed_labels.csv", out / "multispeed_train.csv", out / "multispeed_test.csv")
    ge("train", MULTISPEED, "--labels", f"{o}/multispeed_train.csv", *hs_shank, "--out", f"{o}/multispeed_kernels.yaml")
    ge("process", MULTISPEED, "--kernels", f"{o}/multispeed_kernels.yaml", "--out", f"{w}/multispeed_personal_pred.csv",
       "--quiet")
    ge("evaluate", "--predictions", f"{w}/multispeed_personal_pred.csv", "--truth", MULTISPEED, "--labels",
       f"{o}/multispeed_test.csv", *hs_shank, "--out-dir", f"{o}/multispeed_split",
       "--title", "Multispeed_Walk_AB, kernels from the first halves, tested on the second halves")


# ---------------------------------------------------------------------------------------------
# Tables


def pct(x: float, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f} %"


def metrics(out: Path, name: str) -> dict[str, Any]:
    path = out / name / "metrics.json"
    if not path.is_file():
        sys.exit(f"{path}: missing; run python benchmarks/accuracy.py first")
    return json.loads(path.read_text(encoding="utf-8"))


def per_mode(m: dict[str, Any], key: str, digits: int = 1) -> str:
    return ", ".join(f"{mode} {100 * v[key]:.{digits}f}" for mode, v in m["per_mode"].items())


def reference_agreement() -> dict[str, Any]:
    """Run the README's command and compare with the reference C++ output, sample by sample."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "pred.csv"
        ge("process", MULTISPEED, "--kernels", "able_bodied", "--start", "4000", "--stop", "7000", "--preset", "paper",
           "--out", str(out), "--quiet")
        pred = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    ref = np.loadtxt(REPO / REFERENCE, delimiter=",", skiprows=1, usecols=(0, 1))
    lib = yaml.safe_load((REPO / "config/kernels/able_bodied.yaml").read_text(encoding="utf-8"))
    lengths = {m["name"]: m["length"] for m in lib["modes"]}
    mode_ok = np.array([MODE_IDS[str(m)] for m in pred["mode"]]) == ref[:, 1].astype(int)
    d = np.abs(pred["phase"].astype(float) - ref[:, 0])
    columns = np.minimum(d, 1.0 - d) * np.array([lengths[str(m)] for m in pred["mode"]])  # reference: 1.0 for our 0.0
    return {"samples": len(ref), "mode": int(mode_ok.sum()), "phase_exact": int((columns < 1e-3).sum()),
            "phase_one_column": int((columns <= 1.0 + 1e-4).sum())}


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


def evaluation_tables(out: Path, ref: dict[str, Any]) -> list[str]:
    n = ref["samples"]
    parts = ["### Reference agreement\n\n" + md_table(
        ["comparison", "samples", "same mode", "same phase (exactly)", "phase within one kernel column"],
        [["`gait-estimator process " + MULTISPEED + " --start 4000 --stop 7000 --preset paper` vs `" + REFERENCE + "`",
          f"{n:,}", f"{ref['mode']:,}/{n:,}", f"{ref['phase_exact']:,}/{n:,}", f"{ref['phase_one_column']:,}/{n:,}"]])]
    lib = yaml.safe_load((out / "lg2_kernels.yaml").read_text(encoding="utf-8"))
    rows = [[m["name"], str(m["info"]["strides"]),
             f"{m['info']['duration_mean_s']:.3f} ± {m['info']['duration_std_s']:.3f}", str(m["length"])]
            for m in lib["modes"]]
    found = sum(m["info"]["strides_found"] for m in lib["modes"])
    rejected = sum(len(m["info"]["rejected"]) for m in lib["modes"])
    parts.append(
        "### LG_2_Ramp kernels\n\n" + md_table(["mode", "strides", "duration mean ± std (s)", "N_m"], rows)
        + f"\n\nRejected as outliers: {rejected} of {found} strides; library rate {lib['modes'][0]['sample_rate_hz']:.3f} Hz."
    )
    parts.append("### LG_2_Ramp accuracy\n\n" + md_table(
        ["kernels", *ACCURACY_HEADER],
        [accuracy_row("trained on this recording (**in-sample**)", metrics(out, "lg2_insample")),
         accuracy_row("bundled able_bodied (another session; level = Slow, Med or Fast)", metrics(out, "lg2_able_bodied"))]))
    parts.append("### Multispeed accuracy\n\n" + md_table(
        ["Multispeed", *ACCURACY_HEADER],
        [accuracy_row("able_bodied kernels, steady strides (the comparable case)", metrics(out, "multispeed")),
         accuracy_row("able_bodied kernels, every stride within 15 % (`--all-strides`, speed changes included)",
                      metrics(out, "multispeed_all")),
         accuracy_row("personal kernels: trained on the first half of each steady run, tested on the second",
                      metrics(out, "multispeed_split"))]))
    return parts


def machine(report: dict[str, Any]) -> str:
    m = report["machine"]
    date = f", {report['date']}" if report.get("date") else ""
    return f"{m.get('processor') or m.get('machine', '?')}, {m.get('cpus', '?')} CPUs, Python {m.get('python', '?')}{date}"


def read_report(path: Path, command: str) -> dict[str, Any]:
    if not path.is_file():
        sys.exit(f"{path}: missing; run {command}")
    return json.loads(path.read_text(encoding="utf-8"))


def step_row(path: Path) -> list[str]:
    report = read_report(path, "python benchmarks/performance.py --run")
    rows = {(r["modes"], r["impl"], r.get("preset", "paper")): r["step_us_median"]
            for r in report["results"] if "step_us_median" in r}  # (the process rows are throughputs)
    impl = next(i for _, i, _ in rows if i.startswith("incremental ("))
    med = {m: v for (m, i, p), v in rows.items() if i == impl and p == "paper"}
    lo, hi = min(med), max(med)
    est = {(m, p): rows.get((m, impl.replace("incremental", "estimator"), p)) for m in (lo, hi) for p in ("default", "paper")}
    extra = ("; whole `Estimator.update`, default / paper preset (default calibrated): "
             f"{est[lo, 'default']:,.1f} / {est[lo, 'paper']:,.1f} µs at {lo} modes, "
             f"{est[hi, 'default']:,.0f} / {est[hi, 'paper']:,.0f} µs at {hi}" if all(est.values()) else "")
    return [f"matcher time per sample (median), {lo} / {hi} modes",
            f"{med[lo]:,.1f} µs / {med[hi]:,.0f} µs, paper preset, {impl[len('incremental '):].strip('()')} step{extra} "
            "(a sample arrives every 4,348 µs at 230 Hz)",
            "2.91 µs, 7 modes (C++, Apple M3 Pro)",
            f"`python benchmarks/performance.py --run` (`gait-estimator bench --modes 7,70,700`) on {machine(report)}"]


def another_session_row(path: Path) -> list[str]:
    """LG_2_Ramp at its own stamps with the bundled kernels, default preset: from
    benchmarks/cross_session.py's summary.json; README's command gives the same (test_first_use.py)."""
    d = read_report(path, "python benchmarks/cross_session.py")["results"]["LG2-AB"]["default"]
    return ["mode accuracy on another session: LG_2_Ramp (level, ramps) at its own stamps, bundled kernels "
            "(`level` = Slow, Med or Fast)",
            f"{pct(d['accuracy'])} (steady rows {pct(d['steady_accuracy'])}); phase error "
            f"{pct(d['phase_error_mean'], 2)} of a stride", "99.1 % steady state, 7 modes",
            "the command below; `python benchmarks/cross_session.py`"]


def results_table(ref: dict[str, Any]) -> str:
    """README's three headline rows; the rest is in docs/results.md and docs/performance.md."""
    rows = [
        ["agreement with the reference C++ implementation (Multispeed samples 4000–6999)",
         f"mode {ref['mode']:,}/{ref['samples']:,}; phase {ref['phase_exact']:,}/{ref['samples']:,} exactly, "
         f"{ref['phase_one_column']:,}/{ref['samples']:,} within one kernel column", "—",
         "`python benchmarks/accuracy.py`; `make test` checks it"],
        another_session_row(RESULTS / "cross_session" / "summary.json"),
        step_row(RESULTS / "performance" / "bench.json"),
    ]
    return "### Results\n\n" + md_table(["measure", "result", "paper", "measured with"], rows)


def write_tables(out: Path) -> Path:
    ref = reference_agreement()
    text = "\n\n".join([results_table(ref), *evaluation_tables(out, ref)]) + "\n"
    path = out / "tables.md"
    path.write_text(text, encoding="utf-8")
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tables-only", action="store_true", help="only rewrite tables.md from the results already there")
    args = ap.parse_args(argv)
    if not args.tables_only:
        run(OUT)
    print(f"wrote {write_tables(OUT).relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
