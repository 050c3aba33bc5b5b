"""The controller contract over real DDS: examples/impedance_controller.py subscribed to a real
estimator_node, and the node's units check. Domain IDs 120..121; LOCALHOST discovery."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import REPO, in_process_factory, load_multispeed, offline, stamps_ns, wait_all_answered

from gait_estimator.core.states import NOT_READY, STANDING, WALKING
from gait_estimator.ros.node_client import EstimatorClient

spec = importlib.util.spec_from_file_location("impedance_controller", REPO / "examples" / "impedance_controller.py")
example = importlib.util.module_from_spec(spec)
spec.loader.exec_module(example)


@pytest.fixture
def ros(monkeypatch):
    yield from in_process_factory(monkeypatch, range(120, 122))


class Recorder(example.ImpedanceController):
    """The example, keeping what it saw and commanded."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.seen: list[tuple[int, int, float, float]] = []

    def on_estimate(self, msg) -> None:
        super().on_estimate(msg)
        v = dict(zip(msg.name, msg.position, strict=True))
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        self.seen.append((stamp, int(v["state"]), v["phase"], self.command))


def test_the_example_controller_holds_while_standing_and_follows_walking(ros, multispeed_csv: Path, able_bodied) -> None:
    """Multispeed's first 11 s (standing until the belt starts at 4.6 s, then walking): the
    example sees not ready, stand and walking as offline processing reports them, holds its
    stiffness unless walking and follows the phase when walking. (Its subscription keeps the
    last 10 estimates: one that lags behind skips some, as a controller wants.)"""
    h = ros(120)
    node = h.estimator()
    controller = Recorder(namespace=h.namespace, context=h.context)
    h.nodes.append(controller)
    client = EstimatorClient(h.domain_id, context=h.context, extra_nodes=[node, controller], namespace=h.namespace,
                             estimator_name=f"{h.namespace}/{h.node_name}", node_name="feeder", reliable=True)
    h.clients.append(client)
    rec = load_multispeed(multispeed_csv, 0, 2600)
    stamps = stamps_ns(rec)
    assert client.wait_for_node(10.0, settle_s=0.5)
    client.stream(np.radians(rec.angles_deg), stamps, 230.0)
    wait_all_answered(client, len(rec))
    client.spin_until(lambda: controller.seen and controller.seen[-1][0] == stamps[-1], 5.0)
    assert len(controller.seen) > 0.8 * len(rec) and controller.seen[-1][0] == stamps[-1]
    ref = offline(rec.angles_deg, able_bodied, stamps)
    index = np.searchsorted(stamps, [s for s, _, _, _ in controller.seen])
    states = np.array([s for _, s, _, _ in controller.seen])
    np.testing.assert_array_equal(states, ref.state[index])
    assert {NOT_READY, STANDING, WALKING} <= set(states.tolist())
    for _, state, phase, command in controller.seen:
        if state == WALKING:
            assert 0.0 <= phase < 1.0 and command in {k for pair in example.STIFFNESS.values() for k in pair}
        else:
            assert math.isnan(phase) and command == example.HOLD
    received = client.received
    assert "stand" in received.modes and "" not in received.modes  # nothing on mode while not ready


def test_degrees_sent_as_radians_are_reported(ros, multispeed_csv: Path) -> None:
    """Degrees on a node that reads radians: one warning and WARN diagnostics naming input_units
    within 2 s of stream."""
    h = ros(121)
    node = h.estimator()
    client = h.client(node, reliable=True)
    rec = load_multispeed(multispeed_csv, 5000, 5700)  # 3 s of walking
    assert client.wait_for_node(10.0, settle_s=0.5)
    client.stream(rec.angles_deg, stamps_ns(rec), 230.0)
    client.spin_until(lambda: any("input_units rad" in m for m in client.received.diagnostics_message), 3.0)
    warned = [m for m in client.received.diagnostics_message if "input_units rad" in m]
    assert warned and "degrees read as radians" in warned[0]
    assert 1 in client.received.diagnostics_level  # WARN
