#!/usr/bin/env python3
"""Node latency and throughput tables from the JSON reports of ``gait-estimator bench-node``.

    python benchmarks/node.py          # tables only (part of `make docs`)
    python benchmarks/node.py --run    # first rerun the quiet-machine report (starts a ROS 2 node)
    python benchmarks/node.py --run-imu  # first rerun the two IMU-input sittings (six bench-node runs)
    python benchmarks/node.py --run-dashboard  # first rerun the dashboard's cost (node_dashboard.py)
    python benchmarks/node.py --screenshot docs/img/dashboard.png  # the dashboard's screenshot, only

Reads, in benchmarks/results/node/ (a missing report leaves its column or section out):

* ``bench_node.json``: ``gait-estimator bench-node --profile --json ...`` on a quiet machine;
* ``bench_node_busy.json``: the same while two ``python -c 'while True: pass'`` burners keep both
  cores busy; ``bench_node_busy_rt.json``: with the burners, ``chrt -f 10 gait-estimator bench-node
  --executor events --outputs estimate --rates 1000,2000,3000 --profile --json ...``;
  ``bench_node_busy_priority.json``: the same with ``--thread-priority`` instead of chrt;
* ``bench_node_one_core.json``: ``taskset -c 0 gait-estimator bench-node --profile --json ...``;
* ``bench_node_700.json``: ``gait-estimator bench-node --modes 700 --preset paper --executor events
  --outputs estimate --rates 250,500,1000 --profile --json ...``;
* ``bench_node_imu1_{joint_state,imu,imu_raw}.json``: ``gait-estimator bench-node --input
  joint_state|imu|imu-raw --profile --json ...`` one after the other on a quiet machine (IMU input,
  JointState in the same sitting for comparison); ``bench_node_imu2_*.json``: a second sitting, in
  the reverse order.

Writes ``tables.md`` with the sections ``Two cores``, ``One core``, ``700 modes`` and ``IMU input``
(docs/performance.md, docs/imu.md), and ``results/dashboard/tables.md`` from its
``dashboard.json`` (docs/dashboard.md).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
NODE = ROOT / "benchmarks" / "results" / "node"
REPORTS = {"quiet": "bench_node.json", "busy": "bench_node_busy.json", "busy_rt": "bench_node_busy_rt.json",
           "busy_priority": "bench_node_busy_priority.json",
           "one_core": "bench_node_one_core.json", "modes_700": "bench_node_700.json",
           **{f"imu{n}_{k}": f"bench_node_imu{n}_{k}.json" for n in (1, 2) for k in ("joint_state", "imu", "imu_raw")}}
IMU_RUNS = {"joint_state": "JointState", "imu": "Imu ×4, orientations", "imu_raw": "Imu ×4, gyro + accelerometer"}
"""IMU input runs (file names; ``input_flag`` gives their ``--input``) and their column labels."""


def input_flag(kind: str) -> str:
    """bench-node's ``--input`` value of an IMU_RUNS key."""
    return kind.replace("imu_raw", "imu-raw")
PERIODS_MS = {230: 1000 / 230, 1000: 1.0}
STAGES = {
    "dds_in_and_executor": "input published → node starts handling it (DDS in, executor wake-up, take)",
    "estimator": "node: angle extraction, stamp checks, estimator update",
    "publish": "node: publishing `estimate` (count query, fill, publish)",
    "dds_out": "`estimate` written by the node → the bench's DDS reader (DDS out)",
    "bench_callback": "the bench's DDS reader → its rclpy callback (the bench's own executor)",
    "total_to_dds": "**total, to the bench's DDS reader**",
    "total_to_callback": "total, to the bench's callback",
}


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def ms(x: float | None, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def variant(report: dict[str, Any], executor: str, outputs: str) -> dict[str, Any] | None:
    return next((v for v in report.get("variants", []) if v["executor"] == executor and v["outputs"] == outputs), None)


def step_at(v: dict[str, Any], rate: float) -> dict[str, Any] | None:
    """The sustained (or last) step at ``rate`` of a variant's throughput sweep."""
    steps = [s for s in v.get("throughput", {}).get("steps", []) if s["rate_hz"] == rate]
    return next((s for s in steps if s.get("sustained")), steps[-1] if steps else None)


def lat4(d: dict[str, Any], prefix: str = "") -> str:
    return " / ".join(ms(d.get(f"{prefix}{k}_ms")) for k in ("p50", "p90", "p99", "max")) + " ms"


def lat2(d: dict[str, Any] | None, prefix: str = "") -> str:
    if not d:
        return "—"
    return f"{ms(d.get(prefix + 'p50_ms'))} / {ms(d.get(prefix + 'p99_ms'))} ms"


def rate(v: dict[str, Any]) -> str:
    tp = v.get("throughput")
    if not tp:
        return "—"
    best = tp["max_sustained_rate_hz"]
    tried = tp["rates_tried"]
    if not best:
        return f"none of {', '.join(f'{r:,.0f}' for r in tried)} Hz"
    higher = [r for r in tried if r > best]
    return f"{best:,.0f} Hz" + ("" if higher else " (the highest tried)")


def machine_line(r: dict[str, Any]) -> str:
    m = r["machine"]
    date = f"{r['date']}, " if r.get("date") else ""
    return (f"{date}{m['processor']}, {m['cpus']} vCPUs, Python {m['python']}, numpy {m['numpy']}; "
            f"load average {r['load_average_before'][0]:.2f} before the run, {r['load_average_after'][0]:.2f} after")


def latency_rows(vs: list[dict[str, Any]]) -> list[list[str]]:
    """The rows every side-by-side node table shows, one column per variant in ``vs``: latency at
    230 Hz (to the DDS reader, to the callback) and 1000 Hz, the highest rate, processing time."""
    return [
        ["latency at 230 Hz to the bench's DDS reader, p50 / p90 / p99 / max", *(lat4(v["latency"], "dds_") for v in vs)],
        ["latency at 230 Hz to the bench's callback, p50 / p90 / p99 / max", *(lat4(v["latency"]) for v in vs)],
        ["latency at 1000 Hz, p50 / p99, to the DDS reader; to the callback",
         *(f"{lat2(step_at(v, 1000), 'dds_')}; {lat2(step_at(v, 1000))}" for v in vs)],
        ["highest input rate sustained without drops", *(rate(v) for v in vs)],
        ["node processing time at 230 Hz, mean / max (diagnostics)",
         *(f"{ms(v['latency'].get('node_processing_mean_ms'), 3)} / {ms(v['latency'].get('node_processing_max_ms'))} ms"
           for v in vs)],
    ]


def two_cores(reports: dict[str, dict[str, Any]]) -> str:
    quiet = reports["quiet"]
    busy = reports.get("busy")
    busy_rt = reports.get("busy_rt")
    busy_priority = reports.get("busy_priority")
    states = [("quiet machine", quiet)] + ([("both cores busy (two CPU burners)", busy)] if busy else [])
    states += [("both cores busy, bench and node under `chrt -f 10`", busy_rt)] if busy_rt else []
    if busy_priority:
        states += [(f"both cores busy, `--thread-priority {busy_priority['thread_priority']}`", busy_priority)]
    default = quiet["executor"], quiet["outputs"]
    out = [
        "## Two cores",
        "",
        "`gait-estimator bench-node --profile --json benchmarks/results/node/bench_node.json` on the development "
        f"machine, quiet: {machine_line(quiet)}."
        + (" The same command with two `python -c 'while True: pass'` burners running gives "
           f"`bench_node_busy.json` (load average {busy['load_average_before'][0]:.2f} before, "
           f"{busy['load_average_after'][0]:.2f} after)." if busy else "")
        + (" With the same burners, `chrt -f 10 gait-estimator bench-node --executor events --outputs estimate "
           "--rates 1000,2000,3000 --profile --json benchmarks/results/node/bench_node_busy_rt.json` runs the bench "
           "and the node it starts with real-time (SCHED_FIFO) priority, as a controller would be run." if busy_rt else "")
        + (f" The same with the node's own parameter instead of `chrt`: `gait-estimator bench-node --executor events "
           f"--outputs estimate --rates 1000,2000,3000 --thread-priority {busy_priority['thread_priority']} --profile "
           "--json benchmarks/results/node/bench_node_busy_priority.json` (the node runs with `thread_priority: "
           f"{busy_priority['thread_priority']}`, the bench sets its own threads the same)." if busy_priority else "")
        + f" Library `{quiet['library']}` ({quiet['modes']} modes). Latency is measured from the publication of an input "
        "to the arrival of its `estimate` at the bench's DDS reader (the message info's `received_timestamp`), "
        "and, as in earlier versions of this table, to the bench's rclpy callback (which adds the bench's own "
        "executor, a SingleThreadedExecutor).",
        "",
        f"### Default node (executor `{default[0]}`), the bench subscribing to `estimate` only",
        "",
    ]
    rows = latency_rows([variant(r, *default) for _, r in states])
    out += [table(["measure", *(name for name, _ in states)], rows), ""]

    out += ["### Executors and outputs side by side", ""]
    rows = []
    for name, r in states:
        for v in r["variants"]:
            lt = v["latency"]
            rows.append([name, f"`{v['executor']}`", "all four" if v["outputs"] == "all" else "`estimate`",
                         lat2(lt, "dds_"), lat2(lt), rate(v),
                         f"{ms(lt.get('node_processing_mean_ms'), 3)} ms"])
    out += [table(["machine", "node executor", "bench subscribes to", "230 Hz latency to DDS reader, p50 / p99",
                   "to callback, p50 / p99", "highest rate without drops", "node processing mean"], rows), ""]

    prof = variant(quiet, *default)
    stages = (prof or {}).get("latency", {}).get("profile", {}).get("stages")
    if stages:
        out += [f"### Where the time goes (quiet machine, 230 Hz, executor `{default[0]}`)", "",
                "`--profile` joins the node's `~/profile` rows with the `estimate` message info, per sample "
                f"({prof['latency']['profile']['samples']:,} samples):", ""]
        rows = [[label, ms(stages[k]["mean_ms"], 3), ms(stages[k]["p50_ms"], 3), ms(stages[k]["p99_ms"], 3)]
                for k, label in STAGES.items() if k in stages]
        out += [table(["stage", "mean ms", "p50 ms", "p99 ms"], rows), ""]
        micro = prof.get("micro_us")
        if micro and "serialized_estimate_publish_us" in micro:
            out += ["Per sample in the bench process, publishing `estimate` on a topic nobody subscribes to "
                    "(conversion and serialisation, no delivery): the node's pre-serialised message, patched "
                    f"and published as bytes, {micro['serialized_estimate_publish_us']:.1f} µs; a preallocated "
                    f"JointState filled and published {micro['preallocated_estimate_publish_us']:.1f} µs; a "
                    f"fresh one {micro['fresh_estimate_publish_us']:.1f} µs; a subscriber-count query "
                    f"{micro['subscription_count_query_us']:.1f} µs.", ""]
        elif micro:
            out += ["Per call in the bench process (no DDS): filling the node's preallocated `estimate` message "
                    f"{micro['fill_preallocated_estimate_us']:.1f} µs, building a fresh one "
                    f"{micro['build_fresh_estimate_us']:.1f} µs; a subscriber-count query "
                    f"{micro['subscription_count_query_us']:.1f} µs.", ""]
    return "\n".join(out).rstrip() + "\n"


def one_core(r: dict[str, Any]) -> str:
    v = variant(r, r["executor"], r["outputs"])
    assert v is not None
    lt = v["latency"]
    out = [
        "## One core (`taskset -c 0`)",
        "",
        "`taskset -c 0 gait-estimator bench-node --profile --json benchmarks/results/node/bench_node_one_core.json` "
        f"on the quiet development machine ({machine_line(r)}; {r['machine']['cpus_allowed']} CPU allowed): the node "
        "and the bench process share one core, a stand-in for a Raspberry Pi-class computer (the bench's own "
        f"publishing and receiving compete with the node). Executor `{v['executor']}`, the bench subscribing to "
        "`estimate`.",
        "",
    ]
    rows = [
        ["latency at 230 Hz to the bench's DDS reader, p50 / p90 / p99 / max", lat4(lt, "dds_")],
        ["latency at 230 Hz to the bench's callback, p50 / p90 / p99 / max", lat4(lt)],
        ["highest input rate sustained without drops", rate(v)],
    ]
    budget = []
    for hz, period in PERIODS_MS.items():
        d = lt if hz == 230 else step_at(v, hz)
        if not d or d.get("node_processing_mean_ms") is None:
            continue
        mean, mx = d["node_processing_mean_ms"], d.get("node_processing_max_ms")
        rows.append([f"node processing time at {hz:,} Hz, mean / max (diagnostics)", f"{ms(mean, 3)} / {ms(mx)} ms"])
        budget.append(f"at {hz:,} Hz a sample arrives every {period:.2f} ms; the node's mean processing time of "
                      f"{mean:.3f} ms leaves {period - mean:.2f} ms ({100 * (1 - mean / period):.0f} %) of each period")
    stages = lt.get("profile", {}).get("stages", {})
    if "estimator" in stages and "publish" in stages:
        rows.append(["estimator / publish per sample at 230 Hz, p50 / p99 (`--profile`)",
                     f"{lat2(stages['estimator'])}; {lat2(stages['publish'])}"])
    out += [table(["measure", "one core"], rows), ""]
    if budget:
        out += ["Per-sample budget: " + "; ".join(budget) + ".", ""]
    return "\n".join(out).rstrip() + "\n"


def modes_700(r: dict[str, Any]) -> str:
    v = variant(r, r["executor"], r["outputs"])
    assert v is not None
    lt = v["latency"]
    out = ["## 700 modes", "",
           f"`gait-estimator bench-node --modes {r['modes']} --preset {r['preset']} --executor {r['executor']} --outputs "
           f"{r['outputs']} --rates 250,500,1000 --profile --json benchmarks/results/node/bench_node_700.json` "
           f"(the bundled library cycled to {r['modes']} modes, as `gait-estimator bench --modes`; {machine_line(r)}).",
           "",
           table(["measure", "value"], [
               ["latency at 230 Hz to the bench's DDS reader, p50 / p99",
                f"{ms(lt.get('dds_p50_ms'))} / {ms(lt.get('dds_p99_ms'))} ms"],
               ["latency at 230 Hz to the bench's callback, p50 / p99",
                f"{ms(lt.get('p50_ms'))} / {ms(lt.get('p99_ms'))} ms"],
               ["highest input rate sustained without drops", rate(v)],
               ["node processing at 230 Hz, mean (diagnostics)", f"{ms(lt.get('node_processing_mean_ms'), 3)} ms"],
           ]), ""]
    stages = lt.get("profile", {}).get("stages")
    if stages:
        out += [table(["stage at 230 Hz", "mean ms", "p50 ms", "p99 ms"],
                      [[label, ms(stages[k]["mean_ms"], 3), ms(stages[k]["p50_ms"], 3), ms(stages[k]["p99_ms"], 3)]
                       for k, label in STAGES.items() if k in stages]), ""]
    micro = v.get("micro_us")
    if micro and "serialized_estimate_publish_us" in micro:
        out += [f"Publishing one `estimate` ({3 + 2 * r['modes'] + 6:,} names) in the bench process: pre-serialised "
                f"{micro['serialized_estimate_publish_us']:.0f} µs, preallocated JointState "
                f"{micro['preallocated_estimate_publish_us']:.0f} µs, fresh JointState "
                f"{micro['fresh_estimate_publish_us']:.0f} µs.", ""]
    return "\n".join(out).rstrip() + "\n"


def imu_input(reports: dict[str, dict[str, Any]]) -> str:
    """The node fed four Imu topics (configured mounting) vs JointState, one sitting."""
    runs = [(f"{label}, sitting {n}", input_flag(k), reports[f"imu{n}_{k}"])
            for n in (1, 2) for k, label in IMU_RUNS.items() if f"imu{n}_{k}" in reports]
    vs = [(label, variant(r, r["executor"], r["outputs"])) for label, _, r in runs]
    first = runs[0][2]
    out = ["## IMU input", "",
           "`python benchmarks/node.py --run-imu`: `gait-estimator bench-node --input INPUT --profile --json "
           "benchmarks/results/node/bench_node_imu*.json` "
           f"for INPUT {', '.join(f'`{f}`' for _, f, _ in runs[:3])}, one after the other on the development machine "
           f"({first.get('date', '')}, {first['machine']['processor']}, {first['machine']['cpus']} vCPUs; loads in the "
           "last row); sitting 2 in the reverse order. IMU: `input_type: imu` with configured mounting, per sample "
           "four Imu messages with one stamp; latency from the publication of the last of them; a rate counts samples. Executor "
           f"`{first['executor']}`, the bench subscribing to `estimate`.", ""]
    rows = [
        *latency_rows([v for _, v in vs]),
        ["load average before / after the run",
         *(f"{r['load_average_before'][0]:.2f} / {r['load_average_after'][0]:.2f}" for _, _, r in runs)],
    ]
    return "\n".join([*out, table(["measure", *(label for label, _ in vs)], rows)]) + "\n"


def run_bench(domain_id: int, report: str = "quiet", extra: tuple[str, ...] = ()) -> None:
    """``gait-estimator bench-node --profile --json`` into the report ``report`` (REPORTS), with
    ``extra`` arguments (DDS kept on this machine: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, its own
    ROS_DOMAIN_ID)."""
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_DOMAIN_ID": str(domain_id)}
    NODE.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "gait_estimator.cli", "bench-node", *extra, "--profile", "--json",
                    str(NODE / REPORTS[report])], cwd=ROOT, env=env, check=True)
    stamp(NODE / REPORTS[report])


def run_imu_sittings(domain_id: int) -> None:
    """The two IMU-input sittings: ``--input`` joint_state, imu, imu-raw one after the other, then
    in the reverse order (the machine's load drifts during a sitting)."""
    for n, order in ((1, list(IMU_RUNS)), (2, list(reversed(IMU_RUNS)))):
        for kind in order:
            run_bench(domain_id, f"imu{n}_{kind}", ("--input", input_flag(kind)))


def stamp(path: Path) -> None:
    """Add the date of the run (UTC) to a JSON report, for the tables."""
    report = json.loads(path.read_text(encoding="utf-8"))
    report["date"] = datetime.datetime.now(datetime.timezone.utc).date().isoformat()
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", action="store_true", help="run the quiet-machine bench-node first (about 1 min), then the tables")
    ap.add_argument("--run-imu", action="store_true",
                    help="run the two IMU-input sittings first (six bench-node runs, about 6 min), then the tables")
    ap.add_argument("--run-dashboard", action="store_true",
                    help="run the dashboard's cost first (node with and without it, interleaved; about 3 min)")
    ap.add_argument("--screenshot", type=Path, help="only write the dashboard's screenshot (PNG) here")
    ap.add_argument("--domain-id", type=int, default=91, help="ROS_DOMAIN_ID of the benches (default %(default)s)")
    args = ap.parse_args(argv)
    if args.screenshot:
        from node_dashboard import screenshot

        screenshot(args.screenshot)
        return 0
    if args.run_dashboard:
        from node_dashboard import run_and_write

        run_and_write()
    if args.run:
        run_bench(args.domain_id)
    if args.run_imu:
        run_imu_sittings(args.domain_id)
    reports = {k: json.loads((NODE / f).read_text(encoding="utf-8")) for k, f in REPORTS.items() if (NODE / f).is_file()}
    if "quiet" not in reports:
        sys.exit(f"{NODE / REPORTS['quiet']}: missing; run gait-estimator bench-node --profile --json {NODE / REPORTS['quiet']}")
    parts = [two_cores(reports)]
    if "one_core" in reports:
        parts.append(one_core(reports["one_core"]))
    if "modes_700" in reports:
        parts.append(modes_700(reports["modes_700"]))
    if any(k.startswith("imu1_") for k in reports):
        parts.append(imu_input(reports))
    (NODE / "tables.md").write_text("\n".join(parts), encoding="utf-8")
    print(f"wrote {(NODE / 'tables.md').relative_to(ROOT)}")
    from node_dashboard import write_tables

    if write_tables():
        print("wrote benchmarks/results/dashboard/tables.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
