"""The report of benchmarks/cross_session.py: the targets and ``tables.md`` from its results
(``summary.json``), also for ``python benchmarks/cross_session.py --tables-only``.

Not a script: cross_session.py imports it from its own directory.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from common import md_table, pct, sec

RATE_REFERENCE = "230 Hz"
"""The library-rate variant the other RATES variants are compared with."""

WEARER_SETTINGS = ("default", "paper", "paper + resample")
"""Settings shown per wearer in the SYN-NEW wearers table (when run)."""


# ---------------------------------------------------------------------------------------------
# Targets (issue 10) for the default setting


def targets(res: dict[str, Any]) -> list[dict[str, Any]]:
    R = res["results"]
    rows: list[dict[str, Any]] = []

    def add(what: str, key: str, value: Any, limit: float | None, op: str, paper: Any = None) -> None:
        """A target row; ``limit`` None: a reference row (no target)."""
        ok = None if value is None or limit is None else (value >= limit if op == ">=" else value <= limit)
        rows.append({"target": what, "dataset": key, "op": op, "limit": limit, "default": value, "paper": paper,
                     "pass": ok})

    def get(key: str, setting: str, *path: str) -> Any:
        v: Any = R.get(key, {}).get(setting)
        for p in path:
            v = None if v is None else v.get(p)
        return v

    for key in ("LG2-AB", "SYN-NEW", "SYN-NEW-L"):
        if key not in R or "default" not in R[key]:
            continue
        if key == "LG2-AB":
            add("accuracy", key, get(key, "default", "accuracy"), 0.95, ">=", get(key, "paper", "accuracy"))
            add("level accuracy", key, get(key, "default", "per_mode_accuracy", "level"), 0.90, ">=",
                get(key, "paper", "per_mode_accuracy", "level"))
        else:
            add("accuracy", key, get(key, "default", "accuracy"), 0.97, ">=", get(key, "paper", "accuracy"))
            add("steady accuracy", key, get(key, "default", "steady_accuracy"), 0.97, ">=",
                get(key, "paper", "steady_accuracy"))
        if key != "SYN-NEW-L":
            add("phase error", key, get(key, "default", "phase_error_mean"), 0.015, "<=",
                get(key, "paper", "phase_error_mean"))
        if key == "SYN-NEW" and "default" in R.get("SYN-SELF", {}):
            add("accuracy of the kernels' own person on the route (in-sample reference, no target)", "SYN-SELF",
                get("SYN-SELF", "default", "accuracy"), None, ">=", get("SYN-SELF", "paper", "accuracy"))
    for base in ("RATES-SYN", "RATES-MS"):
        ref = f"{base} {RATE_REFERENCE}"
        if ref not in R or "default" not in R[ref]:
            continue
        for key in [k for k in R if k.startswith(base + " ") and k != ref]:
            diffs = []
            for setting in ("default", "paper"):
                a, b = get(key, setting, "phase_error_mean"), get(ref, setting, "phase_error_mean")
                diffs.append(None if a is None or b is None else abs(a - b))
            add(f"phase error difference from {RATE_REFERENCE}", key, diffs[0], 0.005, "<=", diffs[1])
    return rows


# ---------------------------------------------------------------------------------------------
# Output


def cost_cell(c: dict[str, Any] | None) -> str:
    return "–" if not c else f"{c['median_us']:.0f} ({c['p99_us']:.0f}); {c['per_estimate_us']:.0f}"


def delay_cells(m: dict[str, Any]) -> str:
    if not m["transitions"]:
        return "–"
    miss = f", {m['missed']} missed" if m["missed"] else ""
    return f"{sec(m['mean_delay_s'])} / {sec(m['median_delay_s'])}{miss}"


SUMMARY_DATASETS = ("SYN-NEW", "SYN-NEW-L", "LG2-AB", "MS-LG2")
"""Data sets of the compact settings table (columns)."""


def summary_tables(res: dict[str, Any]) -> str:
    """The two compact tables docs/results.md shows: presets per data set, settings per data set."""
    R, D = res["results"], res["datasets"]
    keys = [k for k in R if not k.startswith("RATES-")]
    rows = []
    for key in keys:
        cells = [f"{key}: {D[key]['title']}"]
        for name in ("default", "paper"):
            m = R[key].get(name)
            cells.append("–" if m is None else f"{pct(m['accuracy'])} ({pct(m['steady_accuracy'])}); "
                         f"{pct(m['phase_error_mean'], 2)}; {delay_cells(m)}")
        rows.append(cells)
    presets = ("### Summary: the two presets on every data set\n\nAccuracy (steady accuracy); phase error mean; "
               "transition delay mean / median.\n\n" + md_table(["data set", "default preset", "paper preset"], rows))
    cols = [k for k in SUMMARY_DATASETS if k in R]
    names = list(dict.fromkeys(n for k in cols for n in R[k]))
    rows = []
    for name in names:
        cells = [name]
        for key in cols:
            m = R[key].get(name)
            cells.append("–" if m is None else f"{pct(m['accuracy'])}; {pct(m['phase_error_mean'], 2)}")
        rows.append(cells)
    settings = ("### Settings: accuracy; phase error mean\n\nEach setting's options are in the Run section of "
                "benchmarks/results/cross_session/tables.md.\n\n" + md_table(["setting", *cols], rows))
    return presets + "\n\n" + settings


def write_tables(res: dict[str, Any], out: Path) -> str:
    """Write ``out/tables.md`` from the results ``res``; its text."""
    R = res["results"]
    parts = [_run_section(res), _targets_section(res), summary_tables(res)]
    parts += [_dataset_section(res, key) for key in R if not key.startswith("RATES-")]
    if "SYN-NEW" in R and res["notes"].get("wearers"):
        parts.append(_wearers_section(res))
    if any(k.startswith("RATES-") for k in R):
        parts.append(_rates_section(res))
    text = "\n\n".join(parts) + "\n"
    (out / "tables.md").write_text(text, encoding="utf-8")
    return text


def _run_section(res: dict[str, Any]) -> str:
    """Command, machine, skipped settings, kernel checks and every setting's options."""
    mach = res["machine"]
    load = ", ".join(f"{v:.1f}" for v in mach["load_average_1min_start_end"])
    cpu = mach["cpu_model"] or mach["processor"]
    text = (f"Measured by `{res['command']}` in {res['runtime_s']:.0f} s on {cpu}, {mach['cpus']} CPUs "
            f"(1-min load average {load} at the start / after timing), Python {mach['python']}, numpy {mach['numpy']}. "
            "Defaults (`{}`) "
            + ("= the paper's values." if res["default_is_paper"] else f"= `{res['default_configuration']}`."))
    if res["skipped_settings"]:
        text += " Skipped (option unknown to this build): " + ", ".join(res["skipped_settings"]) + "."
    checks = res["notes"].get("kernel_checks", {})
    if checks:
        text += " Kernels trained here vs the ones benchmarks/accuracy.py wrote: " + "; ".join(
            f"{name}: " + (c.get("skipped") or (f"max difference {c['max_abs_diff_deg']:.1e} deg" if c["same_modes_and_lengths"]
                                                else "DIFFERENT modes or lengths"))
            for name, c in checks.items()) + "."
    rows = [[name, "`" + json.dumps(opts, ensure_ascii=False) + "`"] for name, opts in res["settings"].items()]
    return ("### Run: command, machine, settings\n\n" + text + " Settings (options on top of the preset "
            "their `preset` key names, `default` if none; `\"<table>\"` = the data set's allowed-transitions file):\n\n"
            + md_table(["setting", "options"], rows))


def _points(v: float | None, digits: int = 2) -> str:
    return "–" if v is None else f"{100 * v:.{digits}f} points"


def _targets_section(res: dict[str, Any]) -> str:
    rows = []
    for t in res["targets"]:
        pass_cell = "–" if t["pass"] is None else ("**pass**" if t["pass"] else "fail")
        op = "≥" if t["op"] == ">=" else "≤"
        fmt = _points if "difference" in t["target"] else pct  # differences in percentage points
        limit = "–" if t["limit"] is None else f"{op} {fmt(t['limit'], 1)}"
        rows.append([t["dataset"], t["target"], limit, fmt(t["paper"], 2), fmt(t["default"], 2), pass_cell])
    return ("### Targets: issue 10 targets with the default options\n\n"
            + md_table(["data", "metric", "target", "paper options", "defaults", "defaults pass?"], rows))


def _dataset_section(res: dict[str, Any], key: str) -> str:
    """One data set: every setting's metrics, then its per-mode accuracy."""
    ds, results = res["datasets"][key], res["results"][key]
    mode_cols = list(dict.fromkeys(n for m in results.values() for n in m["per_mode_accuracy"]))
    rows, mrows = [], []
    first = next(iter(results.values()))
    for name, m in results.items():
        same = f" (= {m['same_configuration_as']})" if m["same_configuration_as"] and name != "default" else ""
        rows.append([f"{name}{same}", pct(m["accuracy"]), pct(m["steady_accuracy"]),
                     f"{pct(m['phase_error_mean'], 2)} ({pct(m['phase_error_max'], 0)})", delay_cells(m),
                     f"{m['switches_per_min']:.1f}", cost_cell(m.get("cost"))])
        cells = []
        for n in mode_cols:
            a, s = m["per_mode_accuracy"].get(n), m["per_mode_steady_accuracy"].get(n)
            cells.append(f"{pct(a)} ({pct(s)} of {m['per_mode_steady_samples'].get(n, 0)})")
        mrows.append([name, *cells])
    rate = ", ".join(f"{r:.0f}" for r in ds["feed_median_rate_hz"])
    head = (f"### {key}: {ds['title']}\n\n{len(ds['parts'])} recording(s), {ds['duration_s']:.0f} s, fed at "
            f"{rate} Hz (median); library {ds['library']} at {ds['library_rate_hz']:.4g} Hz; "
            f"{first['transitions']} truth mode changes ({60 * first['transitions'] / ds['duration_s']:.1f}/min).")
    return (head + "\n\n" + md_table(
        ["setting", "accuracy", "steady", "phase error mean (max)", "transition delay mean / median",
         "mode changes /min", "µs per update: median (p99); mean per estimate"], rows)
        + "\n\nPer truth mode: accuracy (steady accuracy of N steady rows)\n\n" + md_table(["setting", *mode_cols], mrows))


def _wearers_section(res: dict[str, Any]) -> str:
    """The drawn parameters of each SYN-NEW wearer and their accuracy under WEARER_SETTINGS."""
    cols = [s for s in WEARER_SETTINGS if s in res["per_part"].get("SYN-NEW", {})]
    rows = []
    for i, w in enumerate(res["notes"]["wearers"]):
        row = [str(w["seed"]), f"{w['rate_hz']:.0f} Hz ±{100 * w['jitter']:.0f} %", f"{w['cadence']:.3f}",
               ", ".join(f"{o:+.1f}" for o in w["offset_deg"]), ", ".join(f"{g:.2f}" for g in w["gain"]),
               f"{w['noise_sd_deg']:.2f}"]
        for s in cols:
            m = res["per_part"]["SYN-NEW"][s][i]
            row.append(f"{pct(m['accuracy'])}; {pct(m['phase_error_mean'], 2)}")
        rows.append(row)
    return ("### Wearers of SYN-NEW: drawn parameters; accuracy; phase error per setting\n\n" + md_table(
        ["seed", "rate (interval jitter)", "cadence", "offsets (deg)", "amplitude factors", "noise (deg)",
         *cols], rows))


def _rates_section(res: dict[str, Any]) -> str:
    R = res["results"]
    rate_keys = [k for k in R if k.startswith("RATES-")]
    names = list(dict.fromkeys(n for k in rate_keys for n in R[k]))
    rows = []
    for k in rate_keys:
        row = [k.split(" ", 1)[0], k.split(" ", 1)[1]]
        for n in names:
            m = R[k].get(n)
            row.append("–" if m is None else f"{pct(m['accuracy'])}; {pct(m['phase_error_mean'], 2)}")
        rows.append(row)
    return (f"### RATES: one walk at several stream rates; accuracy; phase error (reference {RATE_REFERENCE})\n\n"
            "RATES-SYN = synthetic wearer 0 generated at each rate; RATES-MS = Multispeed (able_bodied kernels) "
            "resampled by cubic spline.\n\n" + md_table(["data", "stream", *names], rows))
