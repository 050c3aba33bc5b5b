"""``sensor_msgs/JointState`` and ``sensor_msgs/Imu`` read from their serialised CDR bytes, as a
ROS 2 subscriber receives them (stamp, names and positions; the Imu fields the IMU input uses),
without building message objects; and an Imu written as such bytes (``write_imu``).

The node subscribes to its input serialised: building a message object (header, stamp, strings,
arrays) costs more than the rest of taking a message. Plain CDR (XCDR1,
either byte order), the encoding ROS 2 Jazzy's middlewares use for these messages: a 4-byte
encapsulation header, then the fields, each aligned to its size relative to the end of that
header. Anything else raises CdrError, and the caller hands the bytes to the middleware's own
deserialiser.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, NamedTuple


class CdrError(ValueError):
    """The bytes are not a plain-CDR message of the type read (other encoding, truncated, invalid)."""


class Stamp(NamedTuple):
    """``builtin_interfaces/Time``: seconds and nanoseconds (the fields the node reads)."""

    sec: int
    nanosec: int


class JointStateFields(NamedTuple):
    """The fields of a JointState the estimator uses."""

    stamp: Stamp
    names: list[str]
    positions: tuple[float, ...]


_BODY = 4  # alignment origin: the end of the encapsulation header
_U32 = (struct.Struct(">I"), struct.Struct("<I"))  # by little-endian flag
_TIME = (struct.Struct(">iI"), struct.Struct("<iI"))


def _byte_order(data: bytes) -> int:
    """1 for little-endian, 0 for big-endian plain CDR; CdrError otherwise (or shorter than a
    header with its stamp)."""
    if len(data) < _BODY + 8 or data[0] != 0 or data[1] > 1:
        raise CdrError(f"not plain CDR (encapsulation {bytes(data[:2]).hex() or 'missing'})")
    return data[1]


def read_stamp(data: bytes) -> Stamp:
    """``header.stamp`` of any CDR-serialised message that starts with a std_msgs/Header (its
    first field), without reading the rest.

    Raises:
        CdrError: not plain CDR (XCDR1), or too short.
    """
    return Stamp(*_TIME[_byte_order(data)].unpack_from(data, _BODY))


def stamp_to_ns(stamp: Any) -> int:
    """A ``builtin_interfaces/Time`` (anything with ``sec`` and ``nanosec``) as integer ns since the epoch."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def with_stamp(data: bytes, stamp_ns: int) -> bytes:
    """``data`` (as for ``read_stamp``) with ``header.stamp`` = ``stamp_ns``, in the message's byte order."""
    buf = bytearray(data)
    _TIME[_byte_order(data)].pack_into(buf, _BODY, *divmod(int(stamp_ns), 1_000_000_000))
    return bytes(buf)


def read_joint_state(data: bytes) -> JointStateFields:
    """Stamp (``header.stamp``), ``name`` and ``position`` of a CDR-serialised JointState.

    Raises:
        CdrError: not plain CDR (XCDR1), or truncated or invalid bytes.
    """
    little = _byte_order(data)
    if len(data) < 16:
        raise CdrError(f"a JointState needs at least 16 bytes, got {len(data)}")
    stamp = read_stamp(data)
    u32 = _U32[little].unpack_from
    end = len(data)
    try:
        p = _BODY + 8
        p += 4 + u32(data, p)[0]  # frame_id
        p += -(p - _BODY) % 4
        count = u32(data, p)[0]
        p += 4
        names = []
        for _ in range(count):  # the message's joints (four for the OSL), not modes
            p += -(p - _BODY) % 4
            n = u32(data, p)[0]
            q = p + 4 + n
            if n == 0 or q > end:  # a CDR string holds at least its terminating NUL
                raise CdrError(f"invalid name at byte {p}")
            names.append(data[p + 4 : q - 1].decode("utf-8"))
            p = q
        p += -(p - _BODY) % 4
        count = u32(data, p)[0]
        p += 4
        if count:
            p += -(p - _BODY) % 8
        if p + 8 * count > end:
            raise CdrError(f"{count} positions do not fit in {end} bytes")
        positions = struct.unpack_from(("<%dd" if little else ">%dd") % count, data, p)
    except (struct.error, UnicodeDecodeError) as exc:
        raise CdrError(f"invalid JointState: {exc}") from None
    return JointStateFields(stamp, names, positions)


class ImuFields(NamedTuple):
    """The fields of a ``sensor_msgs/Imu`` the IMU input uses (quaternion x, y, z, w; rad/s;
    m/s^2)."""

    stamp: Stamp
    frame_id: str
    orientation: tuple[float, float, float, float]
    orientation_cov0: float
    angular_velocity: tuple[float, float, float]
    linear_acceleration: tuple[float, float, float]


# orientation (4 doubles), orientation_covariance[0] (the rest skipped), angular_velocity, its
# covariance (skipped), linear_acceleration, its covariance (skipped): 37 doubles, 8-aligned.
_IMU_TAIL = (struct.Struct(">5d64x3d72x3d72x"), struct.Struct("<5d64x3d72x3d72x"))


def read_imu(data: bytes) -> ImuFields:
    """Stamp, frame_id, orientation, ``orientation_covariance[0]``, angular velocity and linear
    acceleration of a CDR-serialised ``sensor_msgs/Imu``.

    Raises:
        CdrError: not plain CDR (XCDR1), or truncated or invalid bytes.
    """
    little = _byte_order(data)
    try:
        sec, nanosec = _TIME[little].unpack_from(data, _BODY)
        n = _U32[little].unpack_from(data, _BODY + 8)[0]
        p = _BODY + 12 + n
        if n == 0 or p > len(data):  # a CDR string holds at least its terminating NUL
            raise CdrError(f"invalid frame_id length {n}")
        frame_id = data[_BODY + 12 : p - 1].decode("utf-8")
        p += -(p - _BODY) % 8
        ox, oy, oz, ow, cov0, gx, gy, gz, ax, ay, az = _IMU_TAIL[little].unpack_from(data, p)
    except (struct.error, UnicodeDecodeError) as exc:
        raise CdrError(f"invalid Imu: {exc}") from None
    return ImuFields(Stamp(sec, nanosec), frame_id, (ox, oy, oz, ow), cov0, (gx, gy, gz), (ax, ay, az))


def write_imu(stamp_ns: int, frame_id: str, orientation_xyzw: Sequence[float], orientation_cov0: float,
              gyro_rps: Sequence[float], acc_mps2: Sequence[float]) -> bytes:
    """A ``sensor_msgs/Imu`` as plain little-endian CDR bytes (what ``read_imu`` reads), padding
    zero; covariances zero (unknown) except ``orientation_covariance[0]`` (-1: no orientation, REP 145)."""
    name = frame_id.encode("utf-8") + b"\0"
    head = b"\0\1\0\0" + _TIME[1].pack(*divmod(int(stamp_ns), 1_000_000_000)) + _U32[1].pack(len(name)) + name
    head += bytes(-(len(head) - _BODY) % 8)
    return head + _IMU_TAIL[1].pack(*orientation_xyzw, orientation_cov0, *gyro_rps, *acc_mps2)

