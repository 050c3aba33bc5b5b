"""A regular (non-editable) ``pip install`` carries the bundled libraries and data: the package
installed into a fresh prefix finds its kernels and the demo recording there, not in the checkout."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_pip_install_finds_bundled_kernels_and_recordings(tmp_path: Path) -> None:
    src = tmp_path / "src"
    # A copy of the tracked tree, so the build cannot see the checkout's venvs or build folders.
    files = subprocess.run(["git", "-C", str(REPO), "ls-files", "-co", "--exclude-standard", "-z"],
                           check=True, capture_output=True).stdout.decode().split("\0")
    for rel in filter(None, files):
        if rel.startswith(("test/", "benchmarks/")) or not (REPO / rel).is_file():
            continue
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        (src / rel).write_bytes((REPO / rel).read_bytes())
    prefix = tmp_path / "prefix"
    install = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
         "--ignore-installed", "--prefix", str(prefix), str(src)],  # --ignore-installed: leave .venv's copy alone
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert install.returncode == 0, install.stdout + install.stderr
    site = next(prefix.glob("lib/python3*/site-packages"))
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "PYTHONPATH")}
    env["PYTHONPATH"] = str(site)
    code = (
        "import gait_estimator\n"
        "from gait_estimator.io.resources import DEMO_RECORDING, bundled_library_path, data_path\n"
        "from gait_estimator.io.readers import read_recording\n"
        "print(gait_estimator.__file__)\n"
        "print(bundled_library_path())\n"
        "p = data_path(DEMO_RECORDING); print(p); print(len(read_recording(p)))\n"
        "print(data_path('swge/LICENSE'))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    module, library, recording, samples, licence = proc.stdout.split()
    share = prefix / "share" / "gait_estimator"
    assert Path(module).is_relative_to(site)
    static = Path(module).parent / "dashboard" / "static"  # the page's assets: nothing from the internet
    assert {"index.html", "app.js", "app.css"} <= {f.name for f in static.iterdir()}
    assert {"uPlot.iife.min.js", "uPlot.min.css", "LICENSE"} <= {f.name for f in (static / "vendor" / "uplot").iterdir()}
    assert (prefix / "share" / "gait_estimator" / "launch" / "estimator.launch.xml").is_file()
    assert Path(library) == share / "config" / "kernels" / "able_bodied.yaml"
    assert Path(recording) == share / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"
    assert int(samples) == 14170
    assert Path(licence).read_text(encoding="utf-8").startswith("MIT License")
