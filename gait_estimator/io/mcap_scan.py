"""Reading the intact part of an mcap file record by record, without its summary.

An mcap file is the magic ``\\x89MCAP0\\r\\n``, then records (opcode: 1 byte, content length:
uint64 little endian, content), then the magic again. The summary and footer at the end are
optional for reading: schemas, channels and messages all appear in the data section, directly
or inside chunk records (whose content holds records too, uncompressed or compressed with zstd
or lz4). A file cut by a power loss ends inside some record; every record before it is complete.

``iter_mcap`` walks the file from the start and yields every complete message up to the cut,
also the complete messages at the start of a cut chunk: an uncompressed chunk is read record by
record up to the cut, a compressed one is decompressed as far as its data goes (zstd and lz4
frames decompress block by block, so the messages of the last incomplete block are lost).
Pure Python; no ROS, no rosbags.
"""

from __future__ import annotations

import mmap
import struct
import sys
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_DATA_END = 0x0F
RECORD_NAMES = {
    OP_HEADER: "header", OP_FOOTER: "footer", OP_SCHEMA: "schema", OP_CHANNEL: "channel", OP_MESSAGE: "message",
    OP_CHUNK: "chunk", 0x07: "message index", 0x08: "chunk index", 0x09: "attachment", 0x0C: "metadata",
    OP_DATA_END: "data end",
}
MESSAGE_HEADER_BYTES = 22
"""channel id (uint16), sequence (uint32), log time (uint64), publish time (uint64)."""
CHUNK_HEADER_BYTES = 28
"""message start and end time, uncompressed size (uint64 each), uncompressed crc (uint32)."""

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MESSAGE = struct.Struct("<HIQQ")


@dataclass(frozen=True)
class McapSchema:
    """A schema record: ``name`` is the ROS message type, ``data`` its definition."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class McapChannel:
    """A channel record: one topic; ``metadata`` is the raw map (rosbag2 keeps the offered QoS
    there under ``offered_qos_profiles``)."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass
class McapScan:
    """What ``iter_mcap`` found in a file so far.

    Attributes:
        path: The file.
        size: Its size, bytes.
        schemas, channels: By id.
        counts: Messages yielded per channel id.
        first_ns, last_ns: Smallest and largest log time yielded, ns since the epoch (None
            before the first message).
        intact_bytes: Offset just after the last complete record read; inside a cut
            uncompressed chunk, just after its last complete inner record.
        complete: The walk reached the end of the data section (data end record or footer).
        problem: Why the walk stopped early ('' when complete).
    """

    path: Path
    size: int = 0
    schemas: dict[int, McapSchema] = field(default_factory=dict)
    channels: dict[int, McapChannel] = field(default_factory=dict)
    counts: dict[int, int] = field(default_factory=dict)
    first_ns: int | None = None
    last_ns: int | None = None
    intact_bytes: int = 0
    complete: bool = False
    problem: str = ""

    @property
    def messages(self) -> int:
        return sum(self.counts.values())


def has_end_magic(path: str | Path) -> bool:
    """True if the file ends with the mcap magic preceded by a footer record (a closed file)."""
    p = Path(path)
    size = p.stat().st_size
    if size < 8 + 9 + 20 + 8:
        return False
    with p.open("rb") as f:
        f.seek(size - 37)
        tail = f.read(37)
    return tail[-8:] == MAGIC and tail[0] == OP_FOOTER and _U64.unpack_from(tail, 1)[0] == 20


def iter_mcap(scan: McapScan, with_data: bool = True) -> Iterator[tuple[int, int, bytes]]:
    """Yield ``(channel id, log time ns, CDR bytes)`` of every complete message of
    ``scan.path`` in file order, updating ``scan`` as it goes; stops at the cut (or the end of
    the data section). ``with_data=False`` yields empty data (for counting)."""
    with scan.path.open("rb") as f:
        scan.size = f.seek(0, 2)
        if scan.size == 0:
            scan.problem = "the file is empty"
            return
        # mapped, not read: the OS pages the file in as the walk goes; unmapped when the last
        # view of it is gone
        buf = memoryview(mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ))
    if buf[: min(8, scan.size)] != MAGIC[: min(8, scan.size)]:
        scan.problem = "not an mcap file (no magic at the start)"
        return
    if scan.size < len(MAGIC):
        scan.problem = "cut inside the magic at the start"
        return
    yield from _walk(buf, 8, scan.size, 0, scan, with_data, top=True)


def _walk(
    buf: memoryview, pos: int, end: int, file_base: int | None, scan: McapScan, with_data: bool, top: bool
) -> Iterator[tuple[int, int, bytes]]:
    """Records of ``buf[pos:end]``. ``file_base``: file offset of ``buf[0]`` (None inside a
    compressed chunk, where offsets in the file are unknown)."""
    while pos < end:
        if pos + 9 > end:
            if top:
                scan.problem = f"cut inside a record header at byte {pos}"
            return
        op = buf[pos]
        length = _U64.unpack_from(buf, pos + 1)[0]
        body, stop = pos + 9, pos + 9 + length
        if top and pos == 8 and op != OP_HEADER:
            scan.problem = "no header record after the magic"
            return
        if stop > end:
            if top:
                scan.problem = f"cut inside a {RECORD_NAMES.get(op, f'0x{op:02x}')} record that starts at byte {pos}"
                if op == OP_CHUNK:
                    yield from _chunk(buf, body, stop, end, scan, with_data)
            return
        if op == OP_MESSAGE:
            if length < MESSAGE_HEADER_BYTES:
                scan.problem = f"invalid message record at byte {pos}"
                return
            channel, _seq, log_ns, _pub = _MESSAGE.unpack_from(buf, body)
            if channel in scan.channels:  # a message of a channel never seen is skipped
                scan.counts[channel] = scan.counts.get(channel, 0) + 1
                scan.first_ns = log_ns if scan.first_ns is None else min(scan.first_ns, log_ns)
                scan.last_ns = log_ns if scan.last_ns is None else max(scan.last_ns, log_ns)
                yield channel, log_ns, bytes(buf[body + MESSAGE_HEADER_BYTES : stop]) if with_data else b""
        elif op in (OP_SCHEMA, OP_CHANNEL):
            try:
                (_schema if op == OP_SCHEMA else _channel)(buf, body, stop, scan)
            except (struct.error, UnicodeDecodeError):
                scan.problem = f"invalid {RECORD_NAMES[op]} record at byte {pos}"
                return
        elif op == OP_CHUNK and top:
            yield from _chunk(buf, body, stop, stop, scan, with_data)
            if scan.problem:
                return
        elif op in (OP_DATA_END, OP_FOOTER) and top:
            scan.complete = True
            scan.intact_bytes = stop
            return
        pos = stop
        if file_base is not None:
            scan.intact_bytes = file_base + pos


def _chunk(
    buf: memoryview, body: int, stop: int, end: int, scan: McapScan, with_data: bool
) -> Iterator[tuple[int, int, bytes]]:
    """A chunk record whose content runs from ``body`` to ``stop``, of which ``buf`` holds up
    to ``end`` (``end < stop``: the file is cut inside it)."""
    cut = end < stop
    head = body + CHUNK_HEADER_BYTES
    if head + 4 > end:
        return
    _start, _end, size, crc = struct.unpack_from("<QQQI", buf, body)
    name_len = _U32.unpack_from(buf, head)[0]
    records_at = head + 4 + name_len + 8
    if records_at > end:
        return
    compression = bytes(buf[head + 4 : head + 4 + name_len]).decode("utf-8", "replace")
    records_len = _U64.unpack_from(buf, records_at - 8)[0]
    data = buf[records_at : min(records_at + records_len, end)]
    if compression == "":
        yield from _walk(buf, records_at, records_at + len(data), 0, scan, with_data, top=False)
        if cut:
            return
        if crc and zlib.crc32(data) != crc:
            scan.problem = f"chunk at byte {body - 9} fails its checksum"
        return
    try:
        raw = _decompress(compression, bytes(data), complete=not cut)
    except Exception as exc:  # unknown compression or corrupt data: nothing more is readable
        scan.problem = f"chunk at byte {body - 9}: cannot decompress {compression} data ({exc})"
        return
    if not cut and (len(raw) != size or (crc and zlib.crc32(raw) != crc)):
        scan.problem = f"chunk at byte {body - 9} fails its size or checksum check"
        return
    before = scan.messages
    yield from _walk(memoryview(raw), 0, len(raw), None, scan, with_data, top=False)
    if not cut:
        scan.intact_bytes = stop
    elif scan.messages > before:
        scan.intact_bytes = end


def _decompress(compression: str, data: bytes, complete: bool) -> bytes:
    """Decompress chunk data; an incomplete zstd or lz4 frame gives the output of its complete
    blocks."""
    if compression == "zstd":
        if sys.version_info >= (3, 14):  # pragma: no cover
            from compression import zstd  # type: ignore[import-not-found]
        else:
            from backports import zstd  # type: ignore[import-not-found,import-untyped]
        return zstd.decompress(data) if complete else zstd.ZstdDecompressor().decompress(data)
    if compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        return lz4.frame.decompress(data) if complete else lz4.frame.LZ4FrameDecompressor().decompress(data)
    raise ValueError(f"unsupported chunk compression {compression!r}")


def _string(buf: Any, pos: int) -> tuple[str, int]:
    n = _U32.unpack_from(buf, pos)[0]
    return bytes(buf[pos + 4 : pos + 4 + n]).decode("utf-8"), pos + 4 + n


def _schema(buf: memoryview, pos: int, stop: int, scan: McapScan) -> None:
    sid = _U16.unpack_from(buf, pos)[0]
    name, pos = _string(buf, pos + 2)
    encoding, pos = _string(buf, pos)
    n = _U32.unpack_from(buf, pos)[0]
    if pos + 4 + n > stop:
        raise struct.error("schema data beyond its record")
    scan.schemas[sid] = McapSchema(sid, name, encoding, bytes(buf[pos + 4 : pos + 4 + n]))


def _channel(buf: memoryview, pos: int, stop: int, scan: McapScan) -> None:
    cid, schema_id = struct.unpack_from("<HH", buf, pos)
    topic, pos = _string(buf, pos + 4)
    encoding, pos = _string(buf, pos)
    map_end = pos + 4 + _U32.unpack_from(buf, pos)[0]
    pos += 4
    if map_end > stop:
        raise struct.error("channel metadata beyond its record")
    metadata = {}
    while pos < map_end:
        key, pos = _string(buf, pos)
        metadata[key], pos = _string(buf, pos)
    scan.channels[cid] = McapChannel(cid, schema_id, topic, encoding, metadata)
