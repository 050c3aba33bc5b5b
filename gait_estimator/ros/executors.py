"""Executors of ``estimator_node`` (parameter ``executor``) and the spin loop of its ``main``."""

from __future__ import annotations

import gc
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from . import EXECUTORS
from .parameters import StartupError

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


def run(make_node: Callable[[], Node], name: str, args: Sequence[str] | None = None) -> int:
    """``main`` of a node: init, build it with ``make_node``, spin it with the executor its
    ``executor`` parameter names, shut down. Returns 0 after SIGINT/SIGTERM or an external
    shutdown, 2 if it cannot start (StartupError: usage/input errors, as for the CLI)."""
    # SIGINT/SIGTERM only ask the spin loop to stop: rclpy's own handler raises KeyboardInterrupt
    # inside whatever callback runs, which the EventsExecutor then logs as a fatal error. A second
    # signal gets the default action (a hung shutdown still ends).
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()
        signal.signal(signum, signal.SIG_DFL)

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, on_signal)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: Any = None
    executor: Executor | None = None
    code = 0
    try:
        node = make_node()
        kind = node.get_parameter("executor").value
        executor = make_executor(kind, node.context)
        if kind == "events":
            node.max_batch = 1  # one event per message already; see EstimatorNode._on_input
        gc.collect()
        gc.freeze()  # start-up objects stay out of later collections: shorter GC pauses
        spin(node, executor, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        code = 2
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
