"""Executors of ``estimator_node`` (parameter ``executor``) and the spin loop of its ``main``."""

from __future__ import annotations

import threading
from typing import Any

from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node

from . import EXECUTORS

SPIN_PERIOD_S = 0.25
"""``main`` spins with this timeout, never without one: rclpy 7.1's EventsExecutor runs no
callback at all in ``spin()`` or ``spin_once()`` without a timeout (it busy-waits instead)."""


def make_executor(kind: str, context: Any = None) -> Executor:
    """An rclpy executor by ``executor`` parameter value (EXECUTORS)."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single_threaded":
        return SingleThreadedExecutor(context=context)
    raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {kind!r}")


def spin(node: Node, executor: Executor, stop: threading.Event | None = None) -> None:
    """Run ``node``'s callbacks until its context shuts down (rclpy.shutdown) or ``stop`` is set
    (``main``'s SIGINT/SIGTERM handler), within SPIN_PERIOD_S.

    Always with a finite timeout (SPIN_PERIOD_S): rclpy 7.1's EventsExecutor dispatches nothing
    from ``spin()`` or ``spin_once()`` without one (it busy-waits on the clock instead; timers
    and subscriptions never run). That, not the steady-clock diagnostics timer, is why an earlier
    attempt with ``rclpy.spin(node, EventsExecutor())`` published no diagnostics.
    """
    executor.add_node(node)
    try:
        while node.context.ok() and not (stop is not None and stop.is_set()):
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
    finally:
        executor.remove_node(node)
