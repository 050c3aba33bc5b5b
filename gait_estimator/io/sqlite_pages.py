"""Table rows of a SQLite database file read page by page, without SQLite (a cut ``.db3``).

SQLite reaches a table's rows from its root page down through interior b-tree pages. In a bag
recorded for more than a few seconds, the messages table's interior pages are allocated as the
table grows and lie spread over the file, many near its end; a file cut by a power loss has
lost some of them, and SQLite then reports "database disk image is malformed" although most
leaf pages, which hold the rows, are still there. ``table_rows`` reads every table-leaf page
(type 0x0D) of the file on its own: its cells (payload length, rowid, record), with overflow
pages followed when they lie inside the file. Which table a row belongs to is not known here
(that needs the lost interior pages). ``rebuild_rosbag2`` tells rosbag2's tables apart by
their columns and writes what it finds into a new database that SQLite reads as usual.

Format: https://www.sqlite.org/fileformat2.html (sections 1.3, 1.6, 2.1). Pages are read in pure
Python (struct); SQLite only writes the rebuilt database.
"""

from __future__ import annotations

import mmap
import sqlite3
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

SQLITE_MAGIC = b"SQLite format 3\x00"
TABLE_LEAF = 0x0D
_U16 = struct.Struct(">H")
_U32 = struct.Struct(">I")
_INT_SIZES = {1: 1, 2: 2, 3: 3, 4: 4, 5: 6, 6: 8}


class PageRow(NamedTuple):
    """One row of a table-leaf page: page number (from 1), rowid, column values."""

    page: int
    rowid: int
    values: tuple[Any, ...]


class _Corrupt(Exception):
    """A page or cell that does not parse (skipped)."""


def page_size(head: bytes) -> int:
    """The page size from the 100-byte database header (0 if it is not a SQLite header)."""
    if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
        return 0
    size = _U16.unpack_from(head, 16)[0]
    return 65536 if size == 1 else size


def table_rows(path: str | Path) -> Iterator[PageRow]:
    """Every row on every table-leaf page of the file at ``path`` that lies wholly in the
    file, in page order; pages and cells that do not parse are skipped."""
    with Path(path).open("rb") as f:
        size = f.seek(0, 2)
        if size < 100:
            return
        buf = memoryview(mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ))
    psize = page_size(bytes(buf[:100]))
    if not psize:
        return
    usable = psize - buf[20]
    for page in range(1, size // psize + 1):
        start = (page - 1) * psize
        header = start + (100 if page == 1 else 0)
        if buf[header] != TABLE_LEAF:
            continue
        try:
            rows = list(_leaf(buf, start, header, psize, usable, size))
        except (_Corrupt, IndexError, struct.error):
            continue
        for rowid, values in rows:
            yield PageRow(page, rowid, values)


def _leaf(buf: memoryview, start: int, header: int, psize: int, usable: int, size: int) -> Iterator[tuple[int, tuple[Any, ...]]]:
    cells = _U16.unpack_from(buf, header + 3)[0]
    if header + 8 + 2 * cells > start + psize:
        raise _Corrupt
    for i in range(cells):
        off = _U16.unpack_from(buf, header + 8 + 2 * i)[0]
        if not header + 8 + 2 * cells <= start + off < start + usable:
            raise _Corrupt
        pos = start + off
        length, pos = _varint(buf, pos)
        rowid, pos = _varint(buf, pos)
        if rowid >= 1 << 63:
            rowid -= 1 << 64
        yield rowid, _record(_payload(buf, pos, length, psize, usable, size))


def _payload(buf: memoryview, pos: int, length: int, psize: int, usable: int, size: int) -> bytes:
    """A cell's payload: its part on the page, then its overflow pages (fileformat2 1.6)."""
    inline = length
    if length > usable - 35:
        m = (usable - 12) * 32 // 255 - 23
        inline = m + (length - m) % (usable - 4)
        inline = inline if inline <= usable - 35 else m
    parts = [bytes(buf[pos : pos + inline])]
    got = inline
    if got < length:
        nxt = _U32.unpack_from(buf, pos + inline)[0]
        while got < length:
            if not 1 <= nxt <= size // psize:
                raise _Corrupt  # the overflow chain goes past the cut
            o = (nxt - 1) * psize
            part = bytes(buf[o + 4 : o + 4 + min(usable - 4, length - got)])
            parts.append(part)
            got += len(part)
            nxt = _U32.unpack_from(buf, o)[0]
    data = b"".join(parts)
    if len(data) != length:
        raise _Corrupt
    return data


def _record(data: bytes) -> tuple[Any, ...]:
    """Column values of a record: header of serial types, then the values (fileformat2 2.1)."""
    header_len, pos = _varint(data, 0)
    types = []
    while pos < header_len:
        t, pos = _varint(data, pos)
        types.append(t)
    if pos != header_len:
        raise _Corrupt
    values: list[Any] = []
    for t in types:
        if t == 0:
            values.append(None)
        elif t in _INT_SIZES:
            n = _INT_SIZES[t]
            values.append(int.from_bytes(data[pos : pos + n], "big", signed=True))
            pos += n
        elif t == 7:
            values.append(struct.unpack_from(">d", data, pos)[0])
            pos += 8
        elif t in (8, 9):
            values.append(t - 8)
        elif t >= 12:
            n = (t - 12) // 2
            raw = data[pos : pos + n]
            values.append(raw if t % 2 == 0 else raw.decode("utf-8", "replace"))
            pos += n
        else:
            raise _Corrupt
    if pos != len(data):
        raise _Corrupt
    return tuple(values)


def _varint(buf: Any, pos: int) -> tuple[int, int]:
    """A SQLite varint (1 to 9 bytes, big-endian) at ``pos``: (value, position after it)."""
    value = 0
    for i in range(8):
        b = buf[pos + i]
        value = (value << 7) | (b & 0x7F)
        if b < 0x80:
            return value, pos + i + 1
    return (value << 8) | buf[pos + 8], pos + 9


_ROSBAG2_TABLES = """
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT,
                    offered_qos_profiles TEXT, type_description_hash TEXT);
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT, encoding TEXT,
                                 encoded_message_definition TEXT, type_description_hash TEXT);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB);
"""


def rebuild_rosbag2(src: Path, dest: Path) -> tuple[int, int, int]:
    """Write the rosbag2 rows found on the leaf pages of ``src`` to a new database ``dest``.

    Rows are told apart by their columns (the b-tree that says which table a leaf belongs to
    may be lost): messages (rowid, topic id, time, blob), topics (rowid and 4 or 5 texts, the
    name starting with '/'), message definitions (rowid and 4 texts, encoding ros2msg or
    ros2idl). Message ids run 1, 2, 3... in a bag, but a missing id cannot be told from a lost
    page: only the run of consecutive ids from the smallest is kept.

    Returns:
        (first id, messages kept, messages found past the first missing id).
    """
    topics, defs, msgs = {}, {}, {}
    for row in table_rows(src):
        v = row.values
        texts = len(v) > 1 and all(isinstance(x, str) for x in v[1:])
        if len(v) == 4 and type(v[1]) is int and type(v[2]) is int and isinstance(v[3], bytes):
            msgs[row.rowid] = v[1:]
        elif texts and len(v) in (5, 6) and v[1].startswith("/"):
            topics[row.rowid] = (*v[1:], "") if len(v) == 5 else v[1:]
        elif texts and len(v) == 5 and v[2] in ("ros2msg", "ros2idl"):
            defs[row.rowid] = v[1:]
    first = min(msgs, default=1)
    kept = 0
    while first + kept in msgs:
        kept += 1
    con = sqlite3.connect(dest)
    try:
        con.executescript("PRAGMA journal_mode=OFF;" + _ROSBAG2_TABLES)
        con.executemany("INSERT INTO topics VALUES (?, ?, ?, ?, ?, ?)", [(k, *t) for k, t in topics.items()])
        con.executemany("INSERT INTO message_definitions VALUES (?, ?, ?, ?, ?)", [(k, *d) for k, d in defs.items()])
        con.executemany("INSERT INTO messages VALUES (?, ?, ?, ?)", ((i, *msgs[i]) for i in range(first, first + kept)))
        con.commit()
    finally:
        con.close()
    return first, kept, len(msgs) - kept
