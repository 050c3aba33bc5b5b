"""The node process imports no analysis code and no scipy, teaching included: estimator_node in a
fresh process teaches a mode from real strides over real DDS (loopback), then its modules are read.
With numba (the 'fast' extra), numba itself imports scipy when installed: nothing more may come.

Domain IDs 130 and 131; LOCALHOST discovery; a namespace unique to the run.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

TEACH = """
import sys
{block}
try:  # numba's own start-up imports scipy when installed (its version and BLAS checks): before
    from numba import njit
    njit(lambda x: x + 1)(1)
except ImportError:
    pass
before = sorted(m for m in sys.modules if m.split(".")[0] == "scipy")
sys.path.insert(0, {test_dir!r})
import numpy as np
from ros_helpers import BASE_NS, RATE_HZ, InProcess
from gait_estimator.io.readers import read_recording

rec = read_recording({recording!r}, rate_hz=RATE_HZ)
h = InProcess({domain})
try:
    node = h.estimator(kernels="", teach_mode="Slow", teach_strides=3)
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.3)
    n = int(np.searchsorted(rec.time_s, 20.0))
    client.stream(np.radians(rec.angles_deg[:n]), BASE_NS + np.round(rec.time_s[:n] * 1e9).astype(np.int64), RATE_HZ * 4)
    client.spin_until(lambda: node.get_parameter("teach_mode").value == "", 10.0)  # '' again: taught
    print("taught", node.library.mode_names)
finally:
    h.close()
after = sorted(m for m in sys.modules if m.split(".")[0] == "scipy")
print("scipy", "unchanged" if after == before else after, "scipy" in sys.modules)
print("analysis", sorted(m for m in sys.modules if m.startswith("gait_estimator.analysis")))
"""

BLOCK_NUMBA = """
class Blocker:  # the 'fast' extra not installed
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "numba":
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None

sys.meta_path.insert(0, Blocker())
"""


@pytest.mark.parametrize(("domain", "numba"), [(130, False), (131, True)])
def test_a_teaching_node_imports_no_scipy(domain: int, numba: bool) -> None:
    pytest.importorskip("scipy")  # installed, so that importing it would show
    code = TEACH.format(block="" if numba else BLOCK_NUMBA, test_dir=str(REPO / "test"), domain=domain,
                        recording=str(REPO / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"))
    env = {k: v for k, v in os.environ.items() if k != "ROS_STATIC_PEERS"}
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain))
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=300, check=False)
    assert run.returncode == 0, run.stderr
    # with numba, only numba's own start-up has imported scipy
    assert run.stdout.splitlines() == ["taught ['Slow']", f"scipy unchanged {numba}", "analysis []"], run.stdout
