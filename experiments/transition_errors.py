"""Where the synthetic new wearers' wrong rows are: after which mode changes, and reported as what
(docs/new_wearer.md, what 97 % would need).

SYN-NEW's wearers (as in cross_session.py) read with the default options (``--switch-evidence``: and
the opt-in stride-start reader). For every truth mode
change, the time from the change until the new mode is first reported, and the wrong time until
the next change split by what was reported: the previous mode (still held), or a third mode (an
intermediate: a mode that fits the window holding both modes better than either). Rows outside
those spans (steady walking before the first change) are counted apart. Deterministic.

    python experiments/transition_errors.py [--wearers 5] [--switch-evidence 40] [--jobs 2] [--out DIR]
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from bench_common import ROUTE, machine_text, md_table, run_script_jobs, write_report
from synthetic import generate, new_wearer

from gait_estimator.core.estimator import Estimator, EstimatorConfig
from gait_estimator.io.library_io import load_library

REPO = Path(__file__).resolve().parent.parent


def run(job: tuple[int, float]) -> dict[str, Any]:
    """Per truth change of wearer ``seed`` read with the stride-start reader at ``evidence`` (0 = off, the
    default): (from, to, first right s, as previous s, as a third mode s)."""
    seed, evidence = job
    ab = load_library("able_bodied")
    rec = generate(ab, ROUTE, new_wearer(seed), seed=1000 + seed).recording
    assert not evidence, "the stride-start reader was removed (docs/options.md)"
    est = Estimator(ab, EstimatorConfig(), stamped=True)
    reported = np.array([est.update(float(t), x).mode for t, x in zip(rec.time_s, rec.angles_deg, strict=True)])
    ready = np.ones(len(rec), dtype=bool)
    ready[: np.searchsorted(rec.time_s, rec.time_s[0] + est.matcher.max_window / ab.sample_rate_hz)] = False
    labels, t = rec.labels, rec.time_s
    dt = np.diff(t, append=t[-1])  # each row lasts until the next
    changes = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    ends = np.r_[changes[1:], len(labels)]
    events = []
    for c, end in zip(changes, ends, strict=True):
        new, old = labels[c], labels[c - 1]
        got = reported[c:end]
        right = np.flatnonzero(got == new)
        first = float(t[c + right[0]] - t[c]) if right.size else float(t[end - 1] - t[c])
        events.append({
            "from": old, "to": new, "first_right_s": first,
            "as_previous_s": float(dt[c:end][got == old].sum()),
            "as_third_s": float(dt[c:end][(got != old) & (got != new)].sum()),
        })
    before = slice(0, changes[0])
    steady_wrong = float(dt[before][(reported[before] != labels[before]) & ready[before]].sum())
    return {"seed": seed, "events": events, "wrong_before_first_change_s": steady_wrong,
            "duration_s": float(t[-1] - t[0]), "wrong_s": float(dt[(reported != labels) & ready].sum())}


def tables(results: list[dict[str, Any]], command: str, seconds: float, evidence: float) -> str:
    by: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in results:
        for e in r["events"]:
            by[(e["from"], e["to"])].append(e)
    rows = []
    keys = sorted(by, key=lambda k: -np.mean([e["as_previous_s"] + e["as_third_s"] for e in by[k]]))
    for k in keys:
        es = by[k]
        rows.append([f"{k[0]} → {k[1]}", str(len(es)),
                     f"{np.mean([e['first_right_s'] for e in es]):.2f} s",
                     f"{np.mean([e['as_previous_s'] for e in es]):.2f} s",
                     f"{np.mean([e['as_third_s'] for e in es]):.2f} s"])
    prev = sum(e["as_previous_s"] for es in by.values() for e in es)
    third = sum(e["as_third_s"] for es in by.values() for e in es)
    duration = sum(r["duration_s"] for r in results)
    wrong = sum(r["wrong_s"] for r in results)
    changes = sum(len(es) for es in by.values())
    return (
        "### Transition errors: SYN-NEW's wrong time, per mode change\n\n"
        f"Measured by `{command}` in {seconds:.0f} s ({machine_text()}; deterministic). {len(results)} synthetic new "
        "wearers, default options"
        + (f" with the stride-start reader at {evidence:g} deg² s" if evidence else "") + "; "
        f"{changes} truth mode changes in {duration:.0f} s. Per change (mean over wearers): time until the new mode "
        "is first reported, and the wrong time until the next change, reported as the previous mode or as a third "
        "mode.\n\n"
        + md_table(["change", "changes", "first right after", "reported as the previous mode", "reported as a third mode"],
                   rows)
        + f"\n\nIn all: {wrong:.1f} s of {duration:.0f} s wrong once the window is full ({100 * wrong / duration:.1f} %): "
        f"{prev:.1f} s as the previous mode, {third:.1f} s as a third mode, "
        f"{max(0.0, wrong - prev - third):.1f} s elsewhere (steady walking before the first change).\n"
    )


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wearers", type=int, default=5, help="synthetic new wearers (seeds 0..N-1)")
    ap.add_argument("--switch-evidence", type=float, default=0.0,
                    help="switch_evidence_deg2s: the stride-start reader (default 0 = off, as the defaults)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=REPO / "experiments/results/transition_errors", help="output directory")
    args = ap.parse_args(argv)
    if args.switch_evidence:
        ap.error("--switch-evidence: the stride-start reader was removed after commit 1e434ed (docs/options.md)")
    jobs = [(seed, args.switch_evidence) for seed in range(args.wearers)]
    results, command, seconds = run_script_jobs("transition_errors.py", argv, run, jobs, args.jobs)
    write_report(args.out, tables(results, command, seconds, args.switch_evidence), results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
