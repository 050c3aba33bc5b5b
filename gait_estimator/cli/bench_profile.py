"""``bench-node --profile``: where the time of a latency run went, per answered sample, from the
node's ``~/profile`` rows and the message info of the ``estimate`` messages (gait_estimator.cli.bench_node)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np


def _stats_ms(values_ms: np.ndarray) -> dict[str, float]:
    if values_ms.size == 0:
        return {}
    p50, p99 = np.percentile(values_ms, [50, 99])
    return {"mean_ms": float(values_ms.mean()), "p50_ms": float(p50), "p99_ms": float(p99)}


def clock_offset_ns() -> int:
    """time.time_ns() - time.perf_counter_ns(), from the closest of a few back-to-back readings."""
    best = None
    for _ in range(20):
        a = time.perf_counter_ns()
        w = time.time_ns()
        b = time.perf_counter_ns()
        if best is None or b - a < best[0]:
            best = (b - a, w - (a + b) // 2)
    assert best is not None
    return best[1]


def profile_stages(got: Any, stamps: np.ndarray, sent_wall: np.ndarray, recv_wall: np.ndarray) -> dict[str, Any]:
    """Where the time of one latency run went, per answered sample (see bench_node)."""
    from ..ros.node import PROFILE_COLUMNS

    if not got.profile:
        return {"error": "no ~/profile data from the node"}
    rows = np.concatenate(got.profile)
    col = {c: i for i, c in enumerate(PROFILE_COLUMNS)}
    prof_stamp = rows[:, col["stamp_sec"]].astype(np.int64) * 1_000_000_000 + rows[:, col["stamp_nanosec"]].astype(np.int64)
    start = rows[:, col["start_sec"]].astype(np.int64) * 1_000_000_000 + rows[:, col["start_nanosec"]].astype(np.int64)
    by_stamp = {int(st): k for k, st in enumerate(prof_stamp)}
    index = {int(st): i for i, st in enumerate(stamps)}
    est_stamp = np.array(got.estimate_stamp_ns, dtype=np.int64)
    dds = np.array(got.estimate_dds_ns, dtype=np.int64)
    src = np.array(got.estimate_source_ns, dtype=np.int64)
    pairs = [(j, index[int(st)], by_stamp[int(st)]) for j, st in enumerate(est_stamp) if int(st) in index and int(st) in by_stamp]
    if not pairs:
        return {"error": "no answered sample found in the node's ~/profile"}
    j, i, k = (np.array(v, dtype=np.int64) for v in zip(*pairs, strict=True))
    est_ns = rows[k, col["estimator_ns"]]
    pub_ns = rows[k, col["publish_ns"]]
    stages = {
        "dds_in_and_executor": (start[k] - sent_wall[i]) / 1e6,
        "estimator": est_ns / 1e6,
        "publish": pub_ns / 1e6,
        "dds_out": (dds[j] - src[j]) / 1e6,
        "bench_callback": (recv_wall[j] - dds[j]) / 1e6,
        "total_to_dds": (dds[j] - sent_wall[i]) / 1e6,
        "total_to_callback": (recv_wall[j] - sent_wall[i]) / 1e6,
    }
    return {"samples": len(pairs), "stages": {name: _stats_ms(v) for name, v in stages.items()}}


PROFILE_LABELS = {
    "dds_in_and_executor": "input publish -> node starts handling it (DDS in, executor wake-up, take)",
    "estimator": "node: angle extraction, stamp checks, estimator update",
    "publish": "node: publishing (count queries, filling, publish calls)",
    "dds_out": "estimate written by the node -> bench's DDS reader (DDS out)",
    "bench_callback": "bench's DDS reader -> bench's Python callback (bench executor)",
    "total_to_dds": "total: input publish -> estimate at the bench's DDS reader",
    "total_to_callback": "total: input publish -> bench's callback (the latency above)",
}
