"""Teaching live vs training offline, on the bundled Multispeed recording, over real DDS.

    python benchmarks/teach.py [--split half|rest] [--strides 3,5,10,20] [--speed 1]

For every N: an ``estimator_node`` process starts with no library (``kernels: ''``); the
recording is streamed into it (JointState, radians, its own stamps, ``--speed`` x real time);
at each speed's run (Slow, Med, Fast: the strides labelled by cadence as ``label-strides
--all-strides`` labels them; the recording holds 8, 11 and 10) ``teach_mode`` is set shortly
before the run's first heel strike, with ``teach_strides`` = min(N, half the run's strides)
(``--split half``: the held-out split, teach on the first half of each run, score the second) or
min(N, all but 2 of them) (``--split rest``: score the rest of each run). Then, without
restarting the node, the whole recording is streamed again after a 10 s pause in the stamps (a
fresh window and calibration, as offline ``process`` starts) and its estimates are scored on the
strides of each run after the taught ones. Offline, ``train`` on exactly the strides the node
used (the taught library's ``candidate_strides_s``), ``process`` and ``evaluate`` do the same.
Reported: accuracy (all and steady rows), phase error, live - offline in points, kernel
differences, samples lost on the way. Results in benchmarks/results/teach/.

Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and its own ROS_DOMAIN_ID (default 77).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from gait_estimator import load_library
from gait_estimator.analysis.evaluate import PredictionTable, evaluate
from gait_estimator.analysis.labels import LabelRange, duration_labels, labels_from_ranges, merge_steady
from gait_estimator.analysis.strides import heel_strikes
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.strides import stride_bounds
from gait_estimator.io.outputs import ESTIMATE_TOPIC
from gait_estimator.io.process import predict
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording
from gait_estimator.io.resources import data_path

RATE_HZ = 230.0
MODES = ("Slow", "Med", "Fast")
BASE_NS = 1_700_000_000 * 1_000_000_000
TEACH_LEAD_S = 0.3
"""teach_mode is set this long before a run's first heel strike (so that heel strike is a peak
inside the collected samples)."""
PAUSE_S = 10.0
REST_STRIDES = 2
"""--split rest: strides of each run always left to score."""


def runs(rec: Recording) -> dict[str, np.ndarray]:
    """The first run of each speed: its strides (S, 2), as label-strides --all-strides labels them
    (nearest bundled kernel stride duration within 15 %)."""
    hs = heel_strikes(rec, "right_shank", RATE_HZ)
    bounds, _ = stride_bounds(hs.times_s)
    lib = load_library("able_bodied")
    labels = duration_labels(bounds, {m: lib.mode(m).stride_duration_s for m in MODES})
    out: dict[str, np.ndarray] = {}
    for r in merge_steady(labels, steady_only=False):
        if r.mode not in out:
            inside = (bounds[:, 0] >= r.start_s - 1e-9) & (bounds[:, 1] <= r.end_s + 1e-9)
            out[r.mode] = bounds[inside]
    return out


def stream(client, rec: Recording, start_s: float, stop_s: float, speed: float, offset_s: float = 0.0) -> int:
    i0, i1 = np.searchsorted(rec.time_s, [start_s, stop_s])
    stamps = BASE_NS + np.round((rec.time_s[i0:i1] + offset_s) * 1e9).astype(np.int64)
    client.stream(np.radians(rec.angles_deg[i0:i1]), stamps, RATE_HZ * speed)
    return int(i1 - i0)


def table(rec: Recording, trace_modes: list[str], mode_index: np.ndarray, phase: np.ndarray, ready: np.ndarray,
          sse: np.ndarray, sample: np.ndarray, source: str) -> PredictionTable:
    names = np.array(trace_modes, dtype=object)
    return PredictionTable(rec.time_s[sample], sample, names[mode_index], phase, ready, sse, list(trace_modes), source)


def scores(pred: PredictionTable, truth: Recording, hs) -> dict:
    m = evaluate(pred, truth, hs).metrics
    return {
        "accuracy": m["accuracy"], "steady_accuracy": m["steady"]["accuracy"],
        "phase_error_mean": m["phase_error_mean"], "steady_phase_error_mean": m["steady"]["phase_error_mean"],
        "evaluated": m["samples"]["evaluated"], "steady_rows": m["steady"]["samples"],
        "per_mode_accuracy": {k: v["accuracy"] for k, v in m["per_mode"].items()},
    }


def live_run(rec: Recording, plan: dict[str, tuple[int, np.ndarray]], args, out: Path) -> dict:
    """Teach every mode live (pass 1), then stream the whole recording again (pass 2)."""
    from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command
    from gait_estimator.ros.teach_client import TeachClient

    env = local_ros_environment(args.domain_id)
    node = NodeProcess(node_command(["-p", "kernels:=''"]), env)
    client = EstimatorClient(args.domain_id, outputs=(ESTIMATE_TOPIC,))
    teach = None
    try:
        deadline = time.monotonic() + 60
        while not client.wait_for_node(0.5, outputs=False, settle_s=0.5):
            if node.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"estimator_node did not start: {node.output()[-500:]}")
        teach = TeachClient("/estimator_node", args.domain_id, timeout_s=20.0)
        sent, at = 0, 0.0
        taught_at = {}
        for mode in MODES:
            used, strides = plan[mode]
            start = float(strides[0, 0]) - TEACH_LEAD_S
            sent += stream(client, rec, at, start, args.speed)
            teach.set(teach_strides=used, teach_mode=mode)
            at = start
            while teach.get("teach_mode") == mode:  # until the node has its strides
                if at >= rec.time_s[-1]:
                    raise SystemExit(f"{mode} not taught by the end of the recording")
                sent += stream(client, rec, at, at + 1.0, args.speed)
                at += 1.0
            taught_at[mode] = at
        pause = at + PAUSE_S - rec.time_s[0]
        client.spin_for(0.5)
        client.received.clear()
        client.estimate_count = 0
        sent += stream(client, rec, 0.0, rec.time_s[-1] + 1.0, args.speed, offset_s=pause)
        client.spin_for(1.0)
        lib_path = Path(tempfile.mkdtemp()) / f"taught_{args.split}_N{args.current_n}.yaml"
        teach.save(str(lib_path))
        diag = teach.latest_diagnostics()
        pid_alive = node.poll() is None
    finally:
        if teach is not None:
            teach.close()
        client.close()
        node.stop()
        log = node.output()
        node.close()
    lib = load_library(lib_path)
    lib_path.unlink()
    lib_path.parent.rmdir()
    got = client.received
    stamps = np.array(got.estimate_stamp_ns, dtype=np.int64)
    sample = np.round((stamps - BASE_NS) / 1e9 * RATE_HZ - pause * RATE_HZ).astype(np.int64)
    trace = got.trace(lib.mode_names)
    keep = sample >= 0  # late estimates of the first pass (before the pause) are not scored
    sample = sample[keep]
    trace = type(trace)(trace.mode_names, *(np.asarray(getattr(trace, f))[keep] for f in
                                           ("mode_index", "phase", "sse", "phases", "ready")))
    return {
        "library": lib, "sample": sample, "trace": trace, "sent": sent, "taught_at": taught_at,
        "accepted": int(diag["samples_accepted"]), "received": int(diag["samples_received"]),
        "node_alive": pid_alive, "log": [x for x in log.splitlines() if "teach:" in x],
    }


def run_n(n: int, rec: Recording, runs_: dict, args, out: Path) -> dict:
    plan, test_from = {}, {}
    for mode in MODES:
        strides = runs_[mode]
        half = len(strides) // 2
        used = min(n, half) if args.split == "half" else min(n, len(strides) - REST_STRIDES)
        plan[mode] = (used, strides)
        test_from[mode] = half if args.split == "half" else used
    args.current_n = n
    live = live_run(rec, plan, args, out)
    lib = live["library"]
    # scored: the strides of every run after those it was taught on (never a taught stride)
    test_ranges, ranges = [], []
    for mode in MODES:
        taught = np.array(lib.mode(mode).info["candidate_strides_s"])
        strides = runs_[mode]
        start = max(float(strides[test_from[mode], 0]), float(taught[-1, 1]))
        test_ranges.append(LabelRange(start, float(strides[-1, 1]), mode))
        ranges.append(LabelRange(float(taught[0, 0]), float(taught[-1, 1]), mode))
    truth = Recording(rec.time_s, rec.angles_deg, labels=labels_from_ranges(rec.time_s, test_ranges), source=rec.source)
    tr = live["trace"]
    live_pred = table(rec, lib.mode_names, tr.mode_index, tr.phase, tr.ready, tr.sse, live["sample"], "live")
    # offline: train on the strides the node used, process, evaluate
    labelled = Recording(rec.time_s, rec.angles_deg, labels=labels_from_ranges(rec.time_s, ranges), source=rec.source)
    offline_lib = train_library([labelled], "offline", TrainOptions(heel_strikes="right_shank",
                                                                    rate_hz=lib.sample_rate_hz)).library
    # stamped, as the node's JointState input (the reference CSV has no time column: process would not resample)
    pred = predict(Recording(rec.time_s, rec.angles_deg, source=rec.source), offline_lib).trace
    off_pred = table(rec, offline_lib.mode_names, pred.mode_index, pred.phase, pred.ready, pred.sse,
                     np.arange(len(rec)), "offline")
    hs_truth = heel_strikes(rec, "right_shank", RATE_HZ)
    live_s, off_s = scores(live_pred, truth, hs_truth), scores(off_pred, truth, hs_truth)
    kernel_diff = {m: float(np.abs(lib.mode(m).samples - offline_lib.mode(m).samples).max())
                   if lib.mode(m).length == offline_lib.mode(m).length
                   else f"N {lib.mode(m).length} live, {offline_lib.mode(m).length} offline" for m in lib.mode_names}
    return {
        "strides_requested": n,
        "strides_used": {m: lib.mode(m).info["strides"] for m in lib.mode_names},
        "strides_in_run": {m: len(runs_[m]) for m in MODES},
        "split": args.split,
        "test_ranges": [[round(r.start_s, 4), round(r.end_s, 4), r.mode] for r in test_ranges],
        "live": live_s, "offline": off_s,
        "delta_points": {k: None if live_s[k] is None or off_s[k] is None else 100 * (live_s[k] - off_s[k])
                         for k in ("accuracy", "steady_accuracy", "phase_error_mean")},
        "kernel_max_abs_diff_deg": kernel_diff,
        "samples_sent": live["sent"], "samples_accepted": live["accepted"], "estimates_received": len(live["sample"]),
        "second_pass_samples_lost": int(len(rec) - np.unique(live["sample"]).size),
        "node_restarted": not live["node_alive"], "teach_log": live["log"],
    }


def pct(x, digits: int = 1) -> str:
    return "-" if x is None else f"{100 * x:.{digits}f}"


def write_tables(out: Path) -> str:
    """tables.md (the block of docs/teach.md) from the JSON of both splits; returns it."""
    rows = []
    for split in ("half", "rest"):
        path = out / f"teach_{split}.json"
        if not path.exists():
            continue
        for r in json.loads(path.read_text(encoding="utf-8"))["runs"]:
            lv, of = r["live"], r["offline"]
            used = "/".join(str(r["strides_used"].get(m, "-")) for m in MODES)
            diffs = r["kernel_max_abs_diff_deg"].values()
            kd = "; ".join([f"{max(v for v in diffs if isinstance(v, float)):.0e}"]
                           + [v for v in diffs if isinstance(v, str)])
            rows.append(
                f"| {split} | {r['strides_requested']} | {used} | {lv['evaluated']:,} ({lv['steady_rows']:,}) | "
                f"{pct(lv['accuracy'])} / {pct(of['accuracy'])} | {pct(lv['steady_accuracy'])} / "
                f"{pct(of['steady_accuracy'])} | {pct(lv['phase_error_mean'], 2)} / {pct(of['phase_error_mean'], 2)} | "
                f"{kd} | {r['samples_sent'] - r['samples_accepted']} of {r['samples_sent']:,} |"
            )
    text = "\n".join([
        "| split | N | taught Slow/Med/Fast | rows (steady) | accuracy % live / offline | steady rows % "
        "| phase error % | kernel diff (°) | samples lost |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
    ])
    (out / "tables.md").write_text(text + "\n", encoding="utf-8")
    return text


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--strides", default="3,5,10,20", help="N values, comma-separated (default %(default)s)")
    p.add_argument("--split", choices=("half", "rest"), default="half",
                   help="half: teach on at most the first half of each run, score the second half (held out); "
                   "rest: teach on the first N strides (all but the last 2 at most), score the rest of the run")
    p.add_argument("--speed", type=float, default=1.0, help="streaming speed x real time (default %(default)s)")
    p.add_argument("--domain-id", type=int, default=77, help="ROS_DOMAIN_ID (default %(default)s)")
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "teach"))
    p.add_argument("--tables-only", action="store_true", help="only rewrite tables.md from the saved JSON")
    args = p.parse_args(argv)
    if args.tables_only:
        print(write_tables(Path(args.out)))
        return 0
    from gait_estimator.ros.node_client import use_local_ros

    use_local_ros(args.domain_id)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rec = read_recording(data_path("swge/recordings/Multispeed_Walk_AB.csv"), rate_hz=RATE_HZ)
    runs_ = runs(rec)
    rows = []
    for n in [int(v) for v in args.strides.split(",")]:
        r = run_n(n, rec, runs_, args, out)
        rows.append(r)
        print(json.dumps({k: v for k, v in r.items() if k != "teach_log"}), flush=True)
    machine = f"{platform.machine()}, {platform.processor() or 'cpu'}, Python {platform.python_version()}"
    report = {
        "command": "python benchmarks/teach.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": machine,
        "strides_per_run": rows[0]["strides_in_run"] if rows else {}, "runs": rows,
    }
    (out / f"teach_{args.split}.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    print(write_tables(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
