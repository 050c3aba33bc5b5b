"""What the dashboard costs the node, and how fresh the page is; the dashboard's screenshot. Run by
benchmarks/node.py:

    python benchmarks/node.py --run-dashboard      # about 3 min: results/dashboard/{dashboard.json,tables.md}
    python benchmarks/node.py                      # tables only (make docs), results/dashboard/tables.md too
    python benchmarks/node.py --screenshot docs/img/dashboard.png

One estimator_node (ROS_DOMAIN_ID 113, loopback; pinned to CPU 0, everything else to CPU 1, so
that what is measured is the node's own extra work) is fed the bundled Multispeed recording at
230 Hz in blocks, alternately without and with ``gait-estimator dashboard`` attached and a page
client connected to it (A B B A ...), so that both conditions share the machine's state. Per block: the
node's own processing time per sample (its ``~/profile`` topic: estimator update and publishing)
and input -> ``estimate`` at a reliable subscriber; with the dashboard, estimate -> page: the age
of the newest estimate in each frame when a WebSocket client (aiohttp, this process) receives it
(the node's write time from DDS, the system clock of this one machine).
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import MS_CSV, REPO, machine, md_table

from gait_estimator.dashboard.process import start_dashboard
from gait_estimator.io.readers import read_recording
from gait_estimator.ros.node import NODE_NAME, PROFILE_COLUMNS
from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command, use_local_ros

OUT = REPO / "benchmarks" / "results" / "dashboard"
DOMAIN = 113
RATE_HZ = 230.0


class PageClient:
    """A WebSocket client of the dashboard in a thread: the age of each frame's newest estimate."""

    def __init__(self, url: str) -> None:
        self.url = url.replace("http", "ws", 1).split("?")[0] + "ws"
        self.ages_ms: list[float] = []
        self.frames = 0
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=lambda: asyncio.run(self.receive()), daemon=True)
        self.thread.start()

    async def receive(self) -> None:
        import aiohttp

        last = 0
        async with aiohttp.ClientSession() as s, s.ws_connect(self.url) as ws:
            while not self.stop_event.is_set():
                try:
                    msg = await ws.receive(timeout=0.5)
                except asyncio.TimeoutError:
                    continue
                now = time.time_ns()
                frame = json.loads(msg.data)
                if frame.get("type") == "frame":
                    self.frames += 1
                    if frame["source_ns"] and frame["source_ns"] != last:
                        last = frame["source_ns"]
                        self.ages_ms.append((now - last) / 1e6)

    def close(self) -> None:
        self.stop_event.set()
        self.thread.join(timeout=5)


def pct(values: list[float] | np.ndarray) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    return {"n": int(v.size), "p50_ms": float(np.percentile(v, 50)), "p99_ms": float(np.percentile(v, 99))} if v.size else {}


def pin(pid: int, cpu: int) -> None:
    """Every thread of process ``pid`` onto CPU ``cpu`` (when the machine has two or more)."""
    if (os.cpu_count() or 1) > 1:
        subprocess.run(["taskset", "-a", "-p", "-c", str(cpu), str(pid)], check=True, capture_output=True)


def block(client: EstimatorClient, angles: np.ndarray, base_ns: int) -> dict[str, Any]:
    client.received.clear()
    client.estimate_count = 0
    stamps = base_ns + np.arange(len(angles), dtype=np.int64) * round(1e9 / RATE_HZ)
    sent = client.stream(angles, stamps, RATE_HZ)
    client.spin_until(lambda: client.estimate_count >= len(angles), 3.0)
    client.spin_for(1.5)  # the last profile rows come with the next 1 Hz report
    got = client.received
    index = {int(s): i for i, s in enumerate(stamps)}
    answered = [(j, index[int(s)]) for j, s in enumerate(got.estimate_stamp_ns) if int(s) in index]
    j, i = (np.array(v, dtype=np.int64) for v in zip(*answered, strict=True))
    latency = (np.array(got.estimate_recv_ns, dtype=np.int64)[j] - sent[i]) / 1e6
    rows = np.concatenate(got.profile) if got.profile else np.empty((0, len(PROFILE_COLUMNS)))
    col = {c: k for k, c in enumerate(PROFILE_COLUMNS)}
    processing = (rows[:, col["estimator_ns"]] + rows[:, col["publish_ns"]]) / 1e6
    return {"processing": processing.tolist(), "latency": latency.tolist(), "answered": len(answered), "sent": len(angles)}


def run(rounds: int, samples: int) -> dict[str, Any]:
    use_local_ros(DOMAIN)
    env = local_ros_environment(DOMAIN)
    rec = read_recording(REPO / MS_CSV, rate_hz=RATE_HZ)
    angles = np.radians(rec.angles_deg[2000:2000 + samples])
    pin(os.getpid(), 1)
    node = NodeProcess(node_command(["-p", "kernels:=able_bodied"]), env)
    time.sleep(2.0)  # its threads started
    pin(node.pid, 0)
    client = EstimatorClient(DOMAIN, outputs=("estimate",), reliable=True, profile_topic=f"/{NODE_NAME}/profile")
    out: dict[str, Any] = {"machine": machine(), "date": time.strftime("%Y-%m-%d"), "samples_per_block": samples,
                           "load_average_before": os.getloadavg()[0],
                           "rounds": rounds, "without": {"processing": [], "latency": [], "block_p99": []},
                           "with": {"processing": [], "latency": [], "block_p99": [], "page_age": [], "frames_per_s": []}}
    base = 1_700_000_000 * 10**9
    try:
        assert client.wait_for_node(30.0), node.output()
        order = [c for r in range(rounds) for c in (("without", "with") if r % 2 == 0 else ("with", "without"))]
        for k, cond in enumerate(order):
            dash = page = None
            if cond == "with":
                dash, url = start_dashboard(["--port", "0", "--domain-id", str(DOMAIN)], env)
                pin(dash.pid, 1)
                page = PageClient(url)
            client.spin_for(3.0)  # both conditions: the same pause (with: the dashboard's subscriptions match)
            t0, frames0 = time.monotonic(), page.frames if page is not None else 0
            res = block(client, angles, base + k * 100 * 10**9)
            print(f"block {k + 1}/{len(order)} {cond}: answered {res['answered']}/{res['sent']}, node p99 "
                  f"{np.percentile(res['processing'], 99) if res['processing'] else float('nan'):.3f} ms", flush=True)
            out[cond]["processing"] += res["processing"]
            out[cond]["block_p99"].append(float(np.percentile(res["processing"], 99)))
            out[cond]["latency"] += res["latency"]
            if page is not None and dash is not None:
                page.close()
                out["with"]["page_age"] += page.ages_ms
                out["with"]["frames_per_s"].append((page.frames - frames0) / (time.monotonic() - t0))
                dash.close()
    finally:
        client.close()
        node.close()
    summary = {cond: {k: pct(out[cond][k]) for k in ("processing", "latency")} for cond in ("without", "with")}
    for cond in ("without", "with"):
        summary[cond]["block_p99_median_ms"] = float(np.median(out[cond]["block_p99"]))
    summary["with"]["page_age"] = pct(out["with"]["page_age"])
    summary["with"]["frames_per_s"] = float(np.min(out["with"]["frames_per_s"])) if out["with"]["frames_per_s"] else 0.0
    return {k: v for k, v in out.items() if k not in ("without", "with")} | {"summary": summary}


def tables(res: dict[str, Any]) -> str:
    s = res["summary"]
    w, d = s["without"], s["with"]

    def pair(x: dict[str, float], digits: int) -> str:
        return f"{x['p50_ms']:.{digits}f} / {x['p99_ms']:.{digits}f} ms"

    rows = [
        ["node: processing per sample (`~/profile`)", pair(w["processing"], 3), pair(d["processing"], 3),
         f"p99 x{d['processing']['p99_ms'] / w['processing']['p99_ms']:.2f}"],
        ["node: median of the blocks' p99", f"{w['block_p99_median_ms']:.3f} ms", f"{d['block_p99_median_ms']:.3f} ms",
         f"x{d['block_p99_median_ms'] / w['block_p99_median_ms']:.2f}"],
        ["input -> `estimate` (reliable subscriber)", pair(w["latency"], 2), pair(d["latency"], 2), ""],
        ["`estimate` -> page (WebSocket client)", "—", pair(d["page_age"], 1), f"{d['frames_per_s']:.0f} frames/s"],
    ]
    m = res["machine"]
    return (md_table(["p50 / p99", "without", "with dashboard", ""], rows) +
            f"\n\n`python benchmarks/node.py --run-dashboard`, {res['date']}: {res['rounds']} x {res['samples_per_block']:,} "
            f"samples per condition at 230 Hz, interleaved; node on CPU 0, the rest on CPU 1; {m['cpus']} CPUs, load "
            f"average {res.get('load_average_before', float('nan')):.1f} before the run (a shared machine).\n")


def screenshot(path: Path) -> None:
    """The page while the node streams Multispeed (domain 113), saved as PNG."""
    sys.path.insert(0, str(REPO / "test"))
    from browser import chromium

    use_local_ros(DOMAIN)
    env = local_ros_environment(DOMAIN)
    rec = read_recording(REPO / MS_CSV, rate_hz=RATE_HZ)
    node = NodeProcess(node_command(["-p", "kernels:=able_bodied"]), env)
    dash, url = start_dashboard(["--port", "0", "--domain-id", str(DOMAIN)], env)
    client = EstimatorClient(DOMAIN, outputs=("estimate",))
    try:
        assert client.wait_for_node(30.0), node.output()
        with chromium(1280, 1250) as driver:
            driver.get(url)
            angles = np.radians(rec.angles_deg[8600:11000])
            stamps = 1_700_000_000 * 10**9 + np.arange(len(angles), dtype=np.int64) * round(1e9 / RATE_HZ)
            client.stream(angles, stamps, RATE_HZ)
            path.parent.mkdir(parents=True, exist_ok=True)
            driver.save_screenshot(str(path))
    finally:
        client.close()
        node.close()
        dash.close()
    print(f"wrote {path}")


def run_and_write(rounds: int = 8, samples: int = 1150) -> None:
    """The interleaved run (``rounds`` pairs of blocks of ``samples``), into dashboard.json."""
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "dashboard.json").write_text(json.dumps(run(rounds, samples), indent=1) + "\n")


def write_tables() -> bool:
    """tables.md from dashboard.json (False: no report yet)."""
    if not (OUT / "dashboard.json").is_file():
        return False
    (OUT / "tables.md").write_text(tables(json.loads((OUT / "dashboard.json").read_text())))
    return True
