"""``gait-estimator dashboard`` as a child process (``demo --dashboard``, the benchmark, the tests)."""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Mapping, Sequence

from ..core.errors import GaitEstimatorError
from ..ros.node_process import NodeProcess

URL = re.compile(r"open (http://\S+)")


def start_dashboard(options: Sequence[str], env: Mapping[str, str], timeout_s: float = 30.0) -> tuple[NodeProcess, str]:
    """Start the dashboard with ``options`` (e.g. ``--port 0 --domain-id 77``); return the process
    and the URL it printed (with its token), once it listens."""
    proc = NodeProcess([sys.executable, "-m", "gait_estimator.cli", "dashboard", *options], env)
    deadline = time.monotonic() + timeout_s
    while (found := URL.search(proc.output())) is None:
        if proc.poll() is not None or time.monotonic() > deadline:
            out = proc.output().strip().splitlines()
            proc.close()
            raise GaitEstimatorError(f"the dashboard did not start: {out[-1] if out else '(no output)'}")
        time.sleep(0.1)
    return proc, found.group(1)
