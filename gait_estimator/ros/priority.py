"""Real-time scheduling of the node's process (the ``thread_priority`` parameter).

A controller's estimator must not wait behind other work on a busy computer. ros2_control's
controller manager runs its loop under SCHED_FIFO (priority 50) for the same reason; the node
does it on request for every thread of its process (the executor, the middleware's receive
threads), as ``chrt -f P estimator_node`` would, and threads started later inherit it.
Linux only; needs ``CAP_SYS_NICE`` or an ``rtprio`` limit (``/etc/security/limits.conf``).
"""

from __future__ import annotations

import os

MAX_PRIORITY = 99
"""Highest SCHED_FIFO priority on Linux."""


def set_process_priority(priority: int) -> str:
    """Put every thread of this process under SCHED_FIFO at ``priority`` (1..MAX_PRIORITY), or
    back under the normal scheduler (0).

    Returns:
        A one-line description of the result, e.g. ``SCHED_FIFO 50 for 9 threads``.

    Raises:
        ValueError: ``priority`` is not an integer in 0..MAX_PRIORITY.
        OSError: the system refused (PermissionError without the privilege) or cannot do it
            (not Linux); the message says what to do.
    """
    if isinstance(priority, bool) or not isinstance(priority, int) or not 0 <= priority <= MAX_PRIORITY:
        raise ValueError(f"must be an integer in 0..{MAX_PRIORITY} (0 = normal scheduling), got {priority!r}")
    if not hasattr(os, "sched_setscheduler") or not os.path.isdir("/proc/self/task"):
        raise OSError("real-time scheduling is only available on Linux")
    policy = os.SCHED_FIFO if priority else os.SCHED_OTHER
    param = os.sched_param(priority)
    threads = 0
    for tid in sorted(int(t) for t in os.listdir("/proc/self/task")):
        try:
            os.sched_setscheduler(tid, policy, param)
        except ProcessLookupError:  # the thread ended meanwhile
            continue
        except PermissionError:
            raise PermissionError(
                f"not permitted to set SCHED_FIFO {priority} (needs CAP_SYS_NICE or an rtprio limit >= {priority}, "
                "e.g. '@realtime hard rtprio 99' in /etc/security/limits.conf)"
            ) from None
        threads += 1
    return f"SCHED_FIFO {priority} for {threads} threads" if priority else f"normal scheduling for {threads} threads"


def process_priority() -> str:
    """The scheduling of this process's main thread: ``SCHED_FIFO P``, ``SCHED_RR P`` or ``normal``."""
    if not hasattr(os, "sched_getscheduler"):
        return "normal"
    policy = os.sched_getscheduler(0)
    names = {os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR"}
    return f"{names[policy]} {os.sched_getparam(0).sched_priority}" if policy in names else "normal"
