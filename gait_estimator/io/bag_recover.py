"""Reading what a damaged rosbag2 bag still holds (a recording cut by a power loss).

``damage`` says why a bag needs it (the kinds, and what is read of each: docs/bags.md, "Cut
recordings and ``repair``"): a cut ``.mcap`` is read record by record (``mcap_scan.py``); a
``.db3`` from a copy in a temporary directory, where SQLite finishes or rolls back the last
transaction (the originals are never opened for writing), or from its leaf pages when SQLite
stops early (``sqlite_pages.py``); a directory whose ``metadata.yaml`` disagrees with its files
(or, ``count_disagreement``, their message counts) from its storage files alone.

``RecoveredBag`` offers the part of rosbags' ``Reader`` interface the project reads bags with
(``topics``, ``connections``, ``messages(connections)``, ``close``), so topic decoding is the
same for damaged and intact bags. ``Recovery.line()`` is the one-line account of what was
recovered.
"""

from __future__ import annotations

import re
import shutil
import sqlite3
import tempfile
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path, PurePath
from typing import Any, NamedTuple

import yaml

from ..core.errors import RecordingError
from .mcap_scan import McapScan, has_end_magic, iter_mcap
from .sqlite_pages import page_size, rebuild_rosbag2

STORAGE_SUFFIXES = (".mcap", ".db3")
SIDE_FILES = ("-wal", "-journal")


class RawRecord(NamedTuple):
    """One recovered message: topic, ROS message type, log time (ns since the epoch), CDR."""

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class Recovery:
    """What was recovered from a damaged bag (``line()`` says it in one line)."""

    bag: Path
    reason: str
    messages: int
    first_ns: int | None
    last_ns: int | None
    ends: str

    def line(self) -> str:
        span = ""
        if self.first_ns is not None and self.last_ns is not None:
            span = f" over {(self.last_ns - self.first_ns) * 1e-9:.3f} s ({_utc(self.first_ns)} to {_utc(self.last_ns)} UTC)"
        return (
            f"{self.bag}: {self.reason}; recovered {self.messages} message(s){span}; {self.ends}; "
            f"'gait-estimator repair {self.bag}' writes a complete copy"
        )


def _utc(ns: int) -> str:
    return datetime.fromtimestamp(ns * 1e-9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]


# ---------------------------------------------------------------------------------------------
# Finding damage


def damage(path: str | Path) -> str:
    """Why the bag at ``path`` (directory or storage file) needs recovery; '' if it looks
    intact (cheap checks: file ends, sizes, metadata.yaml against the files present)."""
    p = Path(path)
    if p.is_file():
        return file_damage(p)
    meta = p / "metadata.yaml"
    present = _storage_files_in(p)
    if not meta.is_file():
        return "no metadata.yaml" if present else ""
    listed = _listed_files(p)
    if listed is None:
        return "metadata.yaml is unreadable"
    missing = [f.name for f in listed if not f.is_file()]
    if missing:
        return f"metadata.yaml lists {', '.join(missing)}, not in the directory"
    extra = [f.name for f in present if f not in listed]
    if extra:
        return f"{', '.join(extra)} not listed in metadata.yaml"
    for f in listed:
        if why := file_damage(f):
            return f"{f.name}: {why}"
    return ""


def file_damage(f: Path) -> str:
    """Why one storage file needs recovery ('' if it looks intact)."""
    size = f.stat().st_size
    if size == 0:
        return "the file is empty"
    if f.suffix == ".mcap":
        return "" if has_end_magic(f) else "no summary or end magic (cut while recording?)"
    if f.suffix != ".db3":
        return ""
    for side in SIDE_FILES:
        s = f.with_name(f.name + side)
        if s.is_file() and s.stat().st_size > 0:
            return f"{s.name} left beside it (last transaction unfinished)"
    with f.open("rb") as fh:
        head = fh.read(100)
    page = page_size(head)
    if not page:
        return "not a complete SQLite database header"
    pages = int.from_bytes(head[28:32], "big")
    if head[24:28] == head[92:96] and pages and size < page * pages:
        return f"the file ends at byte {size}, its header says {page * pages}"
    if size % page:
        return f"the file size {size} is not a whole number of {page}-byte pages"
    return ""


def count_disagreement(reader: Any) -> str:
    """For a bag directory opened by rosbags: '' if metadata.yaml's message count equals what
    its storage files hold, else what differs."""
    storages = getattr(getattr(reader, "storage", None), "storages", None)
    if not storages:
        return ""
    held = sum(int(s.metadata.message_count) for s in storages)
    said = int(reader.message_count)
    return "" if held == said else f"metadata.yaml says {said} message(s), its files hold {held}"


def _natural(p: Path) -> list[Any]:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]


def _storage_files_in(d: Path) -> list[Path]:
    return sorted((f for f in d.iterdir() if f.suffix in STORAGE_SUFFIXES and f.is_file()), key=_natural)


def _listed_files(d: Path) -> list[Path] | None:
    try:
        info = yaml.safe_load((d / "metadata.yaml").read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        return [d / PurePath(str(x)).name for x in info["relative_file_paths"]]
    except Exception:  # any damage to the YAML means: read the files on their own
        return None


def storage_files(bag: Path) -> list[Path]:
    """The storage files of a bag: metadata.yaml's list (those present) then any others, in
    natural order (``b_2`` before ``b_10``); a storage file is its own list."""
    if bag.is_file():
        return [bag]
    listed = [f for f in _listed_files(bag) or [] if f.is_file()]
    return listed + [f for f in _storage_files_in(bag) if f not in listed]


# ---------------------------------------------------------------------------------------------
# Storage files


@dataclass
class _Topic:
    key: int
    topic: str
    msgtype: str
    msgdef: Any
    digest: str
    serialization_format: str
    qos: list[Any]


@dataclass
class _Storage:
    path: Path
    topics: list[_Topic] = field(default_factory=list)
    counts: dict[int, int] = field(default_factory=dict)
    first_ns: int | None = None
    last_ns: int | None = None
    ends: str = ""

    def iter(self, keys: Collection[int]) -> Iterator[tuple[int, int, bytes]]:
        raise NotImplementedError

    def close(self) -> None:
        pass


def _msgdef(encoding: str, text: str) -> Any:
    """rosbags' MessageDefinition of a recorded definition; format NONE for an unknown encoding."""
    from rosbags.interfaces import MessageDefinition, MessageDefinitionFormat

    fmt = {"ros2msg": MessageDefinitionFormat.MSG, "ros2idl": MessageDefinitionFormat.IDL}.get(encoding)
    return MessageDefinition(fmt, text) if fmt else MessageDefinition(MessageDefinitionFormat.NONE, "")


def _qos(text: str | None) -> list[Any]:
    """The offered QoS profiles recorded for a topic ([] when none)."""
    from rosbags.rosbag2.metadata import parse_qos

    return parse_qos(text) if text else []


class _McapStorage(_Storage):
    def __init__(self, path: Path) -> None:
        super().__init__(path)
        scan = McapScan(path)
        for _ in iter_mcap(scan, with_data=False):
            pass
        for ch in scan.channels.values():
            schema = scan.schemas.get(ch.schema_id)
            msgdef = _msgdef(schema.encoding, schema.data.decode("utf-8", "replace")) if schema else _msgdef("", "")
            name = schema.name if schema else "(unknown type)"
            qos = _qos(ch.metadata.get("offered_qos_profiles"))
            self.topics.append(_Topic(ch.id, ch.topic, name, msgdef, "", ch.message_encoding, qos))
        self.counts, self.first_ns, self.last_ns = dict(scan.counts), scan.first_ns, scan.last_ns
        if not scan.complete:
            where = scan.problem or "at a record boundary"
            self.ends = f"{path.name} ends at byte {scan.size} ({where}); complete records up to byte {scan.intact_bytes}"
        elif not has_end_magic(path):
            self.ends = f"{path.name} ends at byte {scan.size}, inside its summary; its data section is complete"

    def iter(self, keys: Collection[int]) -> Iterator[tuple[int, int, bytes]]:
        for key, log_ns, data in iter_mcap(McapScan(self.path)):
            if key in keys:
                yield key, log_ns, data


class _SqliteStorage(_Storage):
    """Reads a copy of the database (and of any -wal/-journal) so that SQLite may finish or
    roll back the last transaction without touching the original."""

    def __init__(self, path: Path) -> None:
        super().__init__(path)
        self._tmp = tempfile.TemporaryDirectory(prefix="gait_recover_")
        self.copy = Path(self._tmp.name) / path.name
        shutil.copyfile(path, self.copy)
        _whole_pages(self.copy)
        for side in SIDE_FILES:
            if (s := path.with_name(path.name + side)).is_file():
                shutil.copyfile(s, self.copy.with_name(self.copy.name + side))
        problem = self._read()
        if problem:
            self._read_pages(problem)
        elif file_damage(path):
            self.ends = f"{path.name}: every row the database still holds was read (from a copy)"

    def _read(self) -> str:
        """Topics and message counts through SQLite: '' or what stopped the read."""
        self.topics, self.counts, self.first_ns, self.last_ns = [], {}, None, None
        try:
            con = self._connect()
            try:
                cols = [r[1] for r in con.execute("PRAGMA table_info(topics)")]
                defs = {}
                if con.execute("SELECT count(*) FROM sqlite_master WHERE name = 'message_definitions'").fetchone()[0]:
                    for ty, enc, text in con.execute(
                        "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
                    ):
                        defs[ty] = _msgdef(enc, text)
                for row in con.execute("SELECT * FROM topics"):
                    r = dict(zip(cols, row, strict=False))
                    self.topics.append(_Topic(
                        int(r["id"]), r["name"], r["type"], defs.get(r["type"]) or _msgdef("", ""),
                        r.get("type_description_hash") or "", r["serialization_format"], _qos(r.get("offered_qos_profiles")),
                    ))
                return self._count(con)
            finally:
                con.close()
        except sqlite3.DatabaseError as exc:
            return f"unreadable database: {exc}"

    def _read_pages(self, problem: str) -> None:
        """SQLite stopped early (a cut file lost interior b-tree pages): rebuild the tables from
        the leaf pages still in the file (``sqlite_pages``) and read that if it holds more."""
        name, by_sql = self.path.name, sum(self.counts.values())
        rebuilt = self.copy.with_name("pages_" + self.copy.name)
        first, kept, left = rebuild_rosbag2(self.copy, rebuilt)
        self.ends = f"{name}: reading stopped after {by_sql} message(s) ({problem})"
        if kept <= by_sql:
            return
        self.copy = rebuilt
        if again := self._read():
            self.ends = f"{name}: unreadable even page by page ({again})"
            return
        past = f"; {left} row(s) past the first missing id left out" if left else ""
        self.ends = (
            f"{name}: SQLite stopped ({problem}); read page by page: messages with ids {first} to "
            f"{first + kept - 1}, up to the first id whose page is lost{past}"
        )

    def _count(self, con: sqlite3.Connection) -> str:
        problem: list[str] = []
        for key, log_ns, _ in _rows(con, problem):
            self.counts[key] = self.counts.get(key, 0) + 1
            self.first_ns = log_ns if self.first_ns is None else min(self.first_ns, log_ns)
            self.last_ns = log_ns if self.last_ns is None else max(self.last_ns, log_ns)
        return problem[0] if problem else ""

    def _connect(self) -> sqlite3.Connection:
        con = sqlite3.connect(self.copy)
        con.execute("PRAGMA writable_schema=ON")  # read a file shorter than its header says (never written)
        return con

    def iter(self, keys: Collection[int]) -> Iterator[tuple[int, int, bytes]]:
        con = self._connect()
        try:
            for key, log_ns, data in _rows(con, []):
                if key in keys:
                    yield key, log_ns, data
        finally:
            con.close()

    def close(self) -> None:
        self._tmp.cleanup()


def _whole_pages(db: Path) -> None:
    """Cut a copy of a database cut inside a page back to its last whole page: SQLite would
    read the missing part of that page as zeros, i.e. wrong rows, instead of failing."""
    with db.open("r+b") as f:
        page = page_size(f.read(100))
        size = f.seek(0, 2)
        if page and size % page:
            f.truncate(size - size % page)


def _rows(con: sqlite3.Connection, problem: list[str]) -> Iterator[tuple[int, int, bytes]]:
    """Rows of the messages table in id order up to the first unreadable page or invalid row
    (what stopped them goes into ``problem``)."""
    cur = con.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY id")
    try:
        for key, log_ns, data in cur:
            if not (isinstance(key, int) and isinstance(log_ns, int) and isinstance(data, bytes)):
                problem.append("invalid row")
                return
            yield key, log_ns, data
    except sqlite3.DatabaseError as exc:
        problem.append(str(exc))


# ---------------------------------------------------------------------------------------------
# The recovered bag


class RecoveredBag:
    """The readable part of a damaged bag, with the reader interface in the module docstring.

    Connections are merged across storage files by (topic, type, serialization format);
    messages come in file order.
    """

    def __init__(self, bag: Path, reason: str, storages: list[_Storage]) -> None:
        from rosbags.interfaces import Connection, ConnectionExtRosbag2

        self.path = bag
        self._storages = storages
        self._keys: list[dict[int, int]] = []  # per storage: its topic key -> connection index
        merged: dict[tuple[str, str, str], int] = {}
        rows: list[list[Any]] = []
        for st in storages:
            keys = {}
            for t in st.topics:
                i = merged.setdefault((t.topic, t.msgtype, t.serialization_format), len(rows))
                if i == len(rows):
                    rows.append([t, 0])
                rows[i][1] += st.counts.get(t.key, 0)
                keys[t.key] = i
            self._keys.append(keys)
        self.connections = [
            Connection(
                i + 1, t.topic, t.msgtype, t.msgdef, t.digest, n, ConnectionExtRosbag2(t.serialization_format, t.qos), self
            )
            for i, (t, n) in enumerate(rows)
        ]
        firsts = [s.first_ns for s in storages if s.first_ns is not None]
        lasts = [s.last_ns for s in storages if s.last_ns is not None]
        ends = "; ".join(s.ends for s in storages if s.ends) or "every storage file reads to its end"
        self.message_count = sum(c.msgcount for c in self.connections)
        self.recovery = Recovery(bag, reason, self.message_count, min(firsts, default=None), max(lasts, default=None), ends)

    @property
    def topics(self) -> dict[str, Any]:
        from rosbags.interfaces import MessageDefinition, MessageDefinitionFormat, TopicInfo

        out: dict[str, Any] = {}
        for topic in sorted({c.topic for c in self.connections}):
            conns = [c for c in self.connections if c.topic == topic]
            types = {c.msgtype for c in conns}
            defs = {c.msgdef for c in conns}
            out[topic] = TopicInfo(
                types.pop() if len(types) == 1 else None,
                defs.pop() if len(defs) == 1 else MessageDefinition(MessageDefinitionFormat.NONE, ""),
                sum(c.msgcount for c in conns),
                conns,
            )
        return out

    def messages(self, connections: Collection[Any] = ()) -> Iterator[tuple[Any, int, bytes]]:
        """``(connection, log time ns, CDR bytes)`` of the wanted connections (default all), in file order."""
        wanted = {c.id - 1 for c in connections} if connections else set(range(len(self.connections)))
        for st, keys in zip(self._storages, self._keys, strict=True):
            local = {k for k, i in keys.items() if i in wanted}
            for key, log_ns, data in st.iter(local):
                yield self.connections[keys[key]], log_ns, data

    def close(self) -> None:
        for st in self._storages:
            st.close()


def open_recovered(path: str | Path, reason: str) -> RecoveredBag:
    """Read what the damaged bag at ``path`` still holds (``reason``: what is wrong, from
    ``damage``). Raises RecordingError (one line) when not a single message is readable."""
    bag = Path(path)
    files = storage_files(bag)
    storages: list[_Storage] = []
    try:
        for f in files:
            storages.append(_McapStorage(f) if f.suffix == ".mcap" else _SqliteStorage(f))
        recovered = RecoveredBag(bag, reason, storages)
    except BaseException:
        for st in storages:
            st.close()
        raise
    if recovered.message_count == 0:
        recovered.close()
        where = recovered.recovery.ends if files else "no storage file in the directory"
        raise RecordingError(f"{bag}: {reason}; no complete message could be read ({where})")
    return recovered
