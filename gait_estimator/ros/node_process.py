"""Starting ``estimator_node`` as a process, on this machine's DDS only.

``local_ros_environment`` sets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a ``ROS_DOMAIN_ID``
for child processes, ``use_local_ros`` does the same for the current process (call it before
creating a client); ``node_command`` and ``NodeProcess`` start the node.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager
from typing import Any

NODE_MODULE = "gait_estimator.ros.node"


def local_ros_environment(domain_id: int, base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a ROS child process: discovery on localhost only, the given domain."""
    env = dict(os.environ if base is None else base)
    env["ROS_DOMAIN_ID"] = str(int(domain_id))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_STATIC_PEERS", None)
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy, superseded by the range above
    env["PYTHONUNBUFFERED"] = "1"
    return env


def use_local_ros(domain_id: int) -> None:
    """Restrict this process's ROS traffic to localhost and ``domain_id`` (before rclpy.init)."""
    os.environ.update(local_ros_environment(domain_id, {}))
    os.environ.pop("ROS_STATIC_PEERS", None)
    os.environ.pop("ROS_LOCALHOST_ONLY", None)


def node_command(ros_args: Sequence[str] = (), executable: str | Sequence[str] | None = None) -> list[str]:
    """Command line starting estimator_node (default: this interpreter, ``-m gait_estimator.ros.node``)."""
    if executable is None:
        cmd = [sys.executable, "-m", NODE_MODULE]
    elif isinstance(executable, str):
        cmd = [executable]
    else:
        cmd = list(executable)
    return cmd + (["--ros-args", *ros_args] if ros_args else [])



def spin_executor_until(executor: Any, predicate: Callable[[], bool], timeout_s: float, step_s: float = 0.05) -> bool:
    """Spin ``executor`` until ``predicate()`` is true (True) or ``timeout_s`` seconds pass (False)."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        executor.spin_once(timeout_sec=min(left, step_s))
    return True

class Closes(AbstractContextManager):
    """A ``with`` block that ends with ``close()``."""

    def close(self) -> None:
        raise NotImplementedError

    def __exit__(self, *exc: object) -> None:
        self.close()


class NodeProcess(Closes):
    """estimator_node as a child process; its stdout+stderr go to a temporary file.

    Args:
        cmd: Command line (see ``node_command``).
        env: Environment (see ``local_ros_environment``).
    """

    def __init__(self, cmd: Sequence[str], env: Mapping[str, str]) -> None:
        self.cmd = list(cmd)
        self._log = tempfile.TemporaryFile(mode="w+b")
        # A session of its own: a Ctrl-C in the terminal reaches only us; we stop the node.
        self.proc = subprocess.Popen(
            self.cmd, env=dict(env), stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True
        )

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self) -> int | None:
        return self.proc.poll()

    def output(self) -> str:
        """Everything the node printed so far (stdout and stderr)."""
        self._log.flush()
        self._log.seek(0)
        text = self._log.read().decode("utf-8", errors="replace")
        self._log.seek(0, os.SEEK_END)
        return text

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 15.0) -> int:
        """Send ``sig`` and wait; returns the exit code (kills it after ``timeout_s``)."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return int(self.proc.returncode)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.stop(signal.SIGKILL)
        self._log.close()
