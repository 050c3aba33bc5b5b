"""A ``sensor_msgs/JointState`` with fixed names, serialised once and patched for every message.

rclpy converts and serialises every string of a message on every publish: for the node's
``estimate`` (3 + 2M + 6 names for M modes) that is most of the publish cost, more than ten times
the rest at M = 700 (``gait-estimator bench-node --profile`` measures both; docs/performance.md).
The names never change between two option changes, so neither does the layout of
the serialised message: ``SerializedJointState`` keeps its CDR bytes, writes the stamp and the
position values into them in place, and the node publishes the bytes
(``Publisher.publish`` takes serialised messages). Subscribers receive an ordinary JointState.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from ..io.cdr import Stamp

_STAMP = struct.Struct("=iI")  # builtin_interfaces/Time in CDR (host byte order, as serialize_message writes)
_PROBE_SEC, _PROBE_NANOSEC = 0x5A17_C0DE, 0x3B9A_C9FF  # stamp values that cannot occur in the names


def _find_once(buf: bytes, probe: bytes, what: str) -> int:
    at = buf.find(probe)
    if at < 0 or buf.find(probe, at + 1) >= 0:
        raise RuntimeError(f"cannot locate the {what} in the serialised JointState")
    return at


class SerializedJointState:
    """Serialised JointState with ``names`` (and ``frame_id``), no velocity or effort.

    ``values`` is a writable float64 view of the position field inside the bytes (``set_values``
    writes them all from a list); ``set_stamp`` writes ``header.stamp``; ``data()`` returns the
    message ready for ``Publisher.publish``. The layout is checked on construction by
    deserialising a patched copy.
    """

    def __init__(self, names: Sequence[str], frame_id: str = "") -> None:
        k = len(names)
        probe = JointState()
        probe.header.frame_id = frame_id
        probe.header.stamp.sec, probe.header.stamp.nanosec = _PROBE_SEC, _PROBE_NANOSEC
        probe.name = list(names)
        # distinct values whose bytes the names (text) and the stamp cannot contain
        sentinel = -np.pi * 1e-200 * (1.0 + np.arange(k, dtype=np.float64))
        probe.position = sentinel.tolist()
        buf = bytearray(serialize_message(probe))
        self._stamp_at = _find_once(buf, _STAMP.pack(_PROBE_SEC, _PROBE_NANOSEC), "stamp")
        values_at = _find_once(buf, sentinel.tobytes(), "positions") if k else len(buf)
        self._buf = buf
        self._values_at = values_at
        self._values = struct.Struct(f"={k}d")  # host byte order, as serialize_message writes
        self.values = np.frombuffer(buf, dtype=np.float64, count=k, offset=values_at)
        self._check(list(names), frame_id)  # leaves values and stamp at 0

    def set_stamp(self, stamp: TimeMsg | Stamp) -> None:
        """Write ``header.stamp`` (anything with ``sec`` and ``nanosec``)."""
        _STAMP.pack_into(self._buf, self._stamp_at, stamp.sec, stamp.nanosec)

    def set_values(self, values: Sequence[float]) -> None:
        """Write all position values (exactly as many as names) from Python numbers: what
        ``values[:] = ...`` does, without numpy calls."""
        self._values.pack_into(self._buf, self._values_at, *values)

    def data(self) -> bytes:
        """The serialised message (a copy: publish it, then patch the next one)."""
        return bytes(self._buf)

    def _check(self, names: list[str], frame_id: str) -> None:
        k = len(names)
        self.values[:] = np.arange(k) + 0.5
        self.set_stamp(TimeMsg(sec=7, nanosec=11))
        msg = deserialize_message(self.data(), JointState)
        ok = (list(msg.name) == names and msg.header.frame_id == frame_id and
              (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 11) and
              np.array_equal(np.asarray(msg.position), self.values) and not msg.velocity and not msg.effort)
        self.values[:] = 0.0
        self.set_stamp(TimeMsg())
        if not ok:
            raise RuntimeError("patched serialised JointState does not deserialise to the patched values")
