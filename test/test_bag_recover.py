"""Cut and damaged bags (a recording that ended with the battery): every complete message up to
the cut is read, one warning line says what was recovered, ``repair`` writes a complete copy.

No ROS needed: bags are written and checked with rosbags; cuts are made by truncating copies.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader

from gait_estimator.cli.app import main
from gait_estimator.core.errors import RecordingError
from gait_estimator.io.bag import BagRecording, bag_records, read_bag
from gait_estimator.io.bag_recover import damage
from gait_estimator.io.bag_write import write_input_bag
from gait_estimator.io.mcap_scan import MAGIC
from gait_estimator.io.readers import read_recording
from gait_estimator.io.sqlite_pages import table_rows
from gait_estimator.ros.player import load_playlist

START_NS = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def ms_mcap(multispeed_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled Multispeed recording as an mcap bag, converted by the CLI (three chunks)."""
    out = tmp_path_factory.mktemp("ms") / "ms"
    assert main(["convert", str(multispeed_csv), "--out-bag", str(out), "--start-time", "1700000000"]) == 0
    return out


@pytest.fixture(scope="module")
def ms_full(ms_mcap: Path) -> BagRecording:
    return read_bag(ms_mcap)


@pytest.fixture(scope="module")
def message_ends(ms_mcap: Path) -> np.ndarray:
    """File offset just after each message of the uncut mcap file: where its CDR bytes, as
    rosbags reads them, end in the file (found by search, independent of the scanner)."""
    data = _storage(ms_mcap).read_bytes()
    ends, pos = [], 0
    with Reader(ms_mcap) as reader:
        for _, _, raw in reader.messages():
            pos = data.index(bytes(raw), pos)
            ends.append(pos + len(raw))
    return np.array(ends)


@pytest.fixture(scope="module")
def ramp_sqlite(swge: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    rec = read_recording(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv").slice(0, 3000)
    return write_input_bag(rec, tmp_path_factory.mktemp("sq") / "ramp", storage="sqlite3", start_ns=START_NS)


@pytest.fixture(scope="module")
def ms_sqlite(multispeed_csv: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The Multispeed recording (14170 rows, 62 s) as a sqlite3 bag: long enough that the
    messages table has interior b-tree pages spread over the file."""
    rec = read_recording(multispeed_csv)
    return write_input_bag(rec, tmp_path_factory.mktemp("mssq") / "mssq", storage="sqlite3", start_ns=START_NS)


def _sqlite_expected(bag: Path, cut: int) -> tuple[int, int]:
    """For the uncut bag and a cut at byte ``cut``, from SQLite's own walk of the messages
    b-tree (dbstat), independent of the page reader: (messages on the leaves, in id order,
    before the first leaf the cut loses; messages on all leaves wholly before the cut)."""
    con = sqlite3.connect(f"file:{_storage(bag)}?mode=ro", uri=True)
    try:
        pages = cut // con.execute("PRAGMA page_size").fetchone()[0]
        leaves = con.execute(
            "SELECT pageno, ncell FROM dbstat WHERE name = 'messages' AND pagetype = 'leaf' ORDER BY path"
        ).fetchall()
    finally:
        con.close()
    kept = [p <= pages for p, _ in leaves]
    run = kept.index(False) if False in kept else len(kept)
    return sum(n for _, n in leaves[:run]), sum(n for (_, n), k in zip(leaves, kept, strict=True) if k)


def _mcap_expected(data: bytes, cut: int) -> int:
    """Messages an mcap file cut at byte ``cut`` holds whole, by a plain walk of its records
    (independent of mcap_scan): top-level messages, and in chunks the messages whose records
    lie wholly in what decompresses from the chunk bytes before the cut."""
    from backports import zstd
    from lz4 import frame

    def inner(records: bytes) -> int:
        n = pos = 0
        while pos + 9 <= len(records):
            stop = pos + 9 + int.from_bytes(records[pos + 1 : pos + 9], "little")
            if stop > len(records):
                break
            n, pos = n + (records[pos] == 0x05), stop
        return n

    total, pos = 0, 8
    while pos + 9 <= cut:
        op, stop = data[pos], pos + 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
        if op == 0x06:
            name_at = pos + 9 + 28
            name_len = int.from_bytes(data[name_at : name_at + 4], "little")
            comp = data[name_at + 4 : name_at + 4 + name_len].decode()
            at = name_at + 4 + name_len + 8
            part = data[at : min(stop, cut)]
            unpack = {"": bytes, "zstd": zstd.ZstdDecompressor().decompress,
                      "lz4": frame.LZ4FrameDecompressor().decompress}[comp]
            total += inner(unpack(part)) if at <= cut else 0
        elif op == 0x05 and stop <= cut:
            total += 1
        pos = stop
    return total


def _storage(bag: Path) -> Path:
    return next(f for f in bag.iterdir() if f.suffix in (".mcap", ".db3"))


def _cut_copy(bag: Path, dest: Path, size: int, keep_metadata: bool = True) -> Path:
    """A copy of ``bag`` whose storage file keeps only its first ``size`` bytes."""
    shutil.copytree(bag, dest)
    f = _storage(dest)
    data = f.read_bytes()
    f.write_bytes(data[:size])
    if not keep_metadata:
        (dest / "metadata.yaml").unlink()
    return dest


def _same_rows(part: BagRecording, full: BagRecording) -> None:
    """``part`` holds exactly the first rows of ``full``."""
    n = len(part)
    assert 0 < n <= len(full)
    np.testing.assert_array_equal(part.angles_deg, full.angles_deg[:n])
    np.testing.assert_array_equal(part.stamp_ns, full.stamp_ns[:n])
    np.testing.assert_array_equal(part.log_time_ns, full.log_time_ns[:n])
    np.testing.assert_array_equal(part.time_s, full.time_s[:n])


def _digest(path: Path) -> dict[str, str]:
    return {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in sorted(path.iterdir())}


def _warning(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("warning: ") and "recovered" in err
    return err


# ---------------------------------------------------------------------------------------------
# mcap cut at many places


def _cuts(ends: np.ndarray, size: int, header_end: int) -> dict[str, int]:
    mid = len(ends) // 2
    return {
        "inside a message record": int(ends[mid] - 7),
        "right after a message": int(ends[mid]),
        "inside the first chunk": int(ends[100] + 3),
        "inside the last message": int(ends[-1] - 1),
        "inside the summary": size - 50,
        "half of the bytes": size // 2,
    }


@pytest.mark.parametrize(
    "where",
    ["inside a message record", "right after a message", "inside the first chunk", "inside the last message",
     "inside the summary", "half of the bytes"],
)
def test_cut_mcap_gives_every_complete_message(tmp_path, ms_mcap, ms_full, message_ends, where, capsys):
    size = _storage(ms_mcap).stat().st_size
    cut = _cuts(message_ends, size, 0)[where]
    bag = _cut_copy(ms_mcap, tmp_path / "cut", cut)
    before = _digest(bag)
    rec = read_bag(bag)
    expected = int(np.count_nonzero(message_ends <= cut))
    assert len(rec) == expected and rec.messages == expected
    _same_rows(rec, ms_full)
    err = _warning(capsys)
    assert f"recovered {expected} message(s)" in err and f"ends at byte {cut}" in err
    assert rec.recovered and rec.recovered in err
    assert _digest(bag) == before  # the original is never modified


@pytest.mark.parametrize("where", ["zero-length file", "inside the magic", "right after the header"])
def test_cut_mcap_without_a_message_is_an_error(tmp_path, ms_mcap, where, capsys):
    data = _storage(ms_mcap).read_bytes()
    header_end = 8 + 9 + int.from_bytes(data[9:17], "little")
    cut = {"zero-length file": 0, "inside the magic": 5, "right after the header": header_end}[where]
    assert data[:8] == MAGIC and data[8] == 0x01
    bag = _cut_copy(ms_mcap, tmp_path / "cut", cut)
    with pytest.raises(RecordingError, match="no complete message could be read"):
        read_bag(bag)
    assert main(["process", str(bag)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("gait-estimator: error: ") and str(bag) in err
    assert "()" not in err and ("at a record boundary" in err) == (where == "right after the header")


def test_cut_mcap_file_on_its_own_and_without_metadata(tmp_path, ms_mcap, ms_full, message_ends, capsys):
    cut = int(message_ends[5000] + 10)
    bag = _cut_copy(ms_mcap, tmp_path / "cut", cut, keep_metadata=False)
    for path in (bag, _storage(bag)):
        rec = read_bag(path)
        assert len(rec) == 5001
        _same_rows(rec, ms_full)
        err = _warning(capsys)
        assert ("no metadata.yaml" in err) == (path == bag)


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_cut_compressed_chunks_give_their_complete_blocks(tmp_path, ms_full, compression, capsys):
    """ros2 bag record (libmcap) compresses chunks with zstd by default: a cut chunk yields the
    messages of its complete compressed blocks."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2 import storage_mcap as sm

    from gait_estimator.io.bag import typestore

    compress = {"zstd": sm.zstd.compress, "lz4": __import__("lz4.frame").frame.compress}[compression]
    bag = tmp_path / "z"
    with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.storage.compression, writer.storage.compressor = compression, compress
        conn = writer.add_connection("/segment_angles", "sensor_msgs/msg/JointState", typestore=typestore())
        with Reader(ms_full.bag) as reader:
            for _, log_ns, raw in reader.messages():
                writer.write(conn, log_ns, raw)
    f = _storage(bag)
    data = f.read_bytes()
    assert data.count(compression.encode()) >= 3
    f.write_bytes(data[: len(data) // 2])
    expected = _mcap_expected(data, len(data) // 2)
    assert expected > _mcap_expected(data, len(data) // 3) > 0
    rec = read_bag(bag)
    _same_rows(rec, ms_full)
    assert len(rec) == expected
    assert f"recovered {expected} message(s)" in _warning(capsys)


# ---------------------------------------------------------------------------------------------
# sqlite3


@pytest.mark.parametrize("where", ["half", "nine tenths", "a byte short", "header page only", "zero-length file"])
def test_cut_sqlite_gives_what_the_database_holds(tmp_path, ramp_sqlite, where, capsys):
    full = read_bag(ramp_sqlite)
    size = _storage(ramp_sqlite).stat().st_size
    cut = {"half": size // 2, "nine tenths": size * 9 // 10, "a byte short": size - 1, "header page only": 4096,
           "zero-length file": 0}[where]
    bag = _cut_copy(ramp_sqlite, tmp_path / "cut", cut)
    before = _digest(bag)
    if where in ("header page only", "zero-length file"):
        with pytest.raises(RecordingError, match="no complete message could be read"):
            read_bag(bag)
        return
    rec = read_bag(bag)
    _same_rows(rec, full)
    assert len(rec) == _sqlite_expected(ramp_sqlite, cut)[0]
    assert "recovered" in _warning(capsys)
    assert _digest(bag) == before


@pytest.mark.parametrize("percent", [30, 50, 70])
def test_cut_long_sqlite_bag_is_read_page_by_page(tmp_path, ms_sqlite, percent, capsys):
    """A cut 62 s bag has lost interior pages of the messages table (SQLite: "database disk
    image is malformed"): its leaf pages before the cut are read on their own."""
    cut = _storage(ms_sqlite).stat().st_size * percent // 100
    bag = _cut_copy(ms_sqlite, tmp_path / "cut", cut)
    in_order, before_cut = _sqlite_expected(ms_sqlite, cut)
    rec = read_bag(bag)
    _same_rows(rec, read_bag(ms_sqlite))
    assert len(rec) == in_order >= 0.95 * before_cut
    err = _warning(capsys)
    assert f"recovered {in_order} message(s)" in err and f"read page by page: messages with ids 1 to {in_order}" in err


def test_page_reader_gives_every_row_of_an_intact_bag(ms_sqlite):
    with sqlite3.connect(_storage(ms_sqlite)) as con:
        rows = {i: (t, s, d) for i, t, s, d in con.execute("SELECT id, topic_id, timestamp, data FROM messages")}
        topics = con.execute("SELECT * FROM topics").fetchall()
    pages = list(table_rows(_storage(ms_sqlite)))
    assert {r.rowid: r.values[1:] for r in pages if len(r.values) == 4} == rows
    assert [(r.rowid, *r.values[1:]) for r in pages if len(r.values) == 6] == topics


def _kill_during(db: Path, script: str) -> None:
    """Run ``script`` on ``db`` (sqlite3 connection ``con``) in a child that SIGKILLs itself."""
    code = f"import os, signal, sqlite3\ncon = sqlite3.connect({str(db)!r}, isolation_level=None)\n{script}\n" \
           "os.kill(os.getpid(), signal.SIGKILL)\n"
    proc = subprocess.run([sys.executable, "-c", code], check=False)
    assert proc.returncode == -signal.SIGKILL


def test_sqlite_unfinished_transaction_is_rolled_back(tmp_path, ramp_sqlite, capsys):
    """The recorder died inside a transaction that had already spilled pages into the .db3:
    the -journal left beside it restores the last committed state (in a copy)."""
    bag = shutil.copytree(ramp_sqlite, tmp_path / "bag")
    db = _storage(bag)
    _kill_during(db, "con.execute('PRAGMA cache_size=2')\ncon.execute('BEGIN')\n"
                     "con.execute('UPDATE messages SET data = zeroblob(length(data))')\n"
                     "con.execute('INSERT INTO messages(topic_id, timestamp, data) SELECT topic_id, timestamp, data "
                     "FROM messages')")
    journal = db.with_name(db.name + "-journal")
    assert journal.stat().st_size > 0
    assert "last transaction unfinished" in damage(bag)
    before = _digest(bag)
    rec = read_bag(bag)
    full = read_bag(ramp_sqlite)
    assert len(rec) == len(full)
    _same_rows(rec, full)
    _warning(capsys)
    assert _digest(bag) == before  # the journal and database are left as they were


def test_sqlite_committed_wal_frames_are_read(tmp_path, ramp_sqlite, capsys):
    """A write-ahead-log bag (ros2 bag's 'resilient' preset): committed transactions still in
    the -wal are read, the unfinished one is not."""
    bag = shutil.copytree(ramp_sqlite, tmp_path / "bag")
    db = _storage(bag)
    _kill_during(db, "con.execute('PRAGMA journal_mode=WAL')\ncon.execute('PRAGMA wal_autocheckpoint=0')\n"
                     "con.execute('INSERT INTO messages(topic_id, timestamp, data) SELECT topic_id, timestamp + 1000000000000, "
                     "data FROM messages WHERE id <= 100')\n"
                     "con.execute('BEGIN')\ncon.execute('DELETE FROM messages')")
    assert "-wal left beside it" in damage(bag)
    records = list(bag_records(bag))
    with Reader(ramp_sqlite) as reader:
        original = [(t, bytes(raw)) for _, t, raw in reader.messages()]
    assert [(r.log_time_ns, r.data) for r in records] == original + [(t + 10**12, d) for t, d in original[:100]]
    assert {r.topic for r in records} == {"/segment_angles"}


# ---------------------------------------------------------------------------------------------
# metadata.yaml missing or wrong


@pytest.mark.parametrize("damaged", ["missing", "unreadable", "wrong count", "wrong file name"])
def test_metadata_that_disagrees_with_the_files(tmp_path, ms_mcap, ms_full, damaged, capsys):
    bag = shutil.copytree(ms_mcap, tmp_path / "bag")
    meta = bag / "metadata.yaml"
    if damaged == "missing":
        meta.unlink()
    elif damaged == "unreadable":
        meta.write_text("rosbag2_bagfile_information: [\n")
    elif damaged == "wrong count":
        doc = yaml.safe_load(meta.read_text())
        doc["rosbag2_bagfile_information"]["message_count"] = 99
        meta.write_text(yaml.safe_dump(doc))
    else:
        _storage(bag).rename(bag / "renamed_0.mcap")
    rec = read_bag(bag)
    assert len(rec) == len(ms_full)
    _same_rows(rec, ms_full)
    err = _warning(capsys)
    why = {"missing": "no metadata.yaml", "unreadable": "metadata.yaml is unreadable",
           "wrong count": "metadata.yaml says 99 message(s), its files hold 14170", "wrong file name": "not in the directory"}
    assert why[damaged] in err and "every storage file reads to its end" in err


# ---------------------------------------------------------------------------------------------
# every command, and repair


def test_commands_read_a_cut_bag(tmp_path, ms_mcap, ms_full, message_ends, capsys):
    cut = int(message_ends[6000] - 1)
    bag = _cut_copy(ms_mcap, tmp_path / "cut", cut)
    assert main(["convert", str(bag), "--out", str(tmp_path / "x.csv")]) == 0
    _warning(capsys)
    assert len(read_recording(tmp_path / "x.csv")) == 6000
    playlist = load_playlist(bag)  # play (ROS-free part)
    assert len(playlist) == 6000
    _warning(capsys)
    assert main(["train", str(bag), "--mode", "Slow", "--out", str(tmp_path / "lib.yaml")]) == 0
    _warning(capsys)


def test_acceptance_multispeed_cut_at_half(tmp_path, ms_mcap, message_ends, capsys):
    """Issue 31: process recovers >= 95 % of the messages before a cut at 50 % of the bytes,
    warns in one line and exits 0; repair writes a bag rosbags reads as an ordinary bag."""
    size = _storage(ms_mcap).stat().st_size
    bag = _cut_copy(ms_mcap, tmp_path / "cut", size // 2)
    before_cut = int(np.count_nonzero(message_ends <= size // 2))
    assert main(["process", str(bag), "--out", str(tmp_path / "pred.csv")]) == 0
    err = _warning(capsys)
    n = int(re.search(r"recovered (\d+) message", err).group(1))
    assert len(read_bag(bag)) == n
    capsys.readouterr()
    print(f"messages before the cut {before_cut}, recovered {n} ({100 * n / before_cut:.1f} %)")
    assert n >= 0.95 * before_cut
    original = _digest(bag)
    assert main(["repair", str(bag)]) == 0
    out = tmp_path / "cut_repaired"
    assert f"wrote {out} (mcap, {n} messages" in capsys.readouterr().out
    assert _digest(bag) == original
    with AnyReader([out]) as reader:
        assert reader.message_count == n
        assert sum(1 for _ in reader.messages()) == n
    assert damage(out) == ""
    with Reader(ms_mcap) as full, Reader(out) as rep:
        assert [bytes(r) for _, _, r in rep.messages()] == [bytes(r) for _, _, r in full.messages()][:n]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_repair_writes_a_complete_bag_and_never_overwrites(tmp_path, ms_mcap, ramp_sqlite, storage, capsys):
    src = ms_mcap if storage == "mcap" else ramp_sqlite
    bag = _cut_copy(src, tmp_path / "cut", _storage(src).stat().st_size * 2 // 3)
    out = tmp_path / "fixed"
    assert main(["repair", str(bag), "--out", str(out)]) == 0
    capsys.readouterr()
    assert next(out.glob("*.db3" if storage == "sqlite3" else "*.mcap"))
    assert (out / "metadata.yaml").is_file() and damage(out) == ""
    rec, part = read_bag(out), read_bag(bag)
    capsys.readouterr()
    np.testing.assert_array_equal(rec.angles_deg, part.angles_deg)
    np.testing.assert_array_equal(rec.log_time_ns, part.log_time_ns)
    before = _digest(out)
    assert main(["repair", str(bag), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"gait-estimator: error: {out}: already exists; repair writes a new bag directory"
    assert _digest(out) == before
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging left


FOO_MSG = "float64 x\nstring label\n"


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_repair_keeps_topics_of_custom_types(tmp_path, ms_full, storage, capsys):
    """A topic of a type the Jazzy type store does not know is copied with the definition
    recorded in the bag, as ros2 bag reindex keeps it."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)  # not the project's cached store, which must not learn Foo
    ts.register(get_types_from_msg(FOO_MSG, "my_pkg/msg/Foo"))
    foo_type = ts.types["my_pkg/msg/Foo"]
    bag = tmp_path / "cust"
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(bag, version=8, storage_plugin=plugin) as writer, Reader(ms_full.bag) as reader:
        angles = writer.add_connection("/segment_angles", "sensor_msgs/msg/JointState", typestore=ts)
        foo = writer.add_connection("/foo", "my_pkg/msg/Foo", typestore=ts)
        for k, (_, log_ns, raw) in enumerate(reader.messages()):
            writer.write(angles, log_ns, raw)
            if k % 10 == 0:
                writer.write(foo, log_ns, bytes(ts.serialize_cdr(foo_type(float(k), f"n{k}"), "my_pkg/msg/Foo")))
    f = _storage(bag)
    f.write_bytes(f.read_bytes()[: f.stat().st_size * 2 // 3])
    kept = list(bag_records(bag, ["/foo"]))
    assert len(kept) > 100
    assert main(["repair", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "not copied" not in out and f"/foo {len(kept)}" in out
    with AnyReader([tmp_path / "cust_repaired"]) as reader:
        conn = next(c for c in reader.connections if c.topic == "/foo")
        assert conn.msgtype == "my_pkg/msg/Foo" and conn.msgdef.data == FOO_MSG
        got = [reader.deserialize(raw, conn.msgtype) for _, _, raw in reader.messages(connections=[conn])]
    assert [(m.x, m.label) for m in got] == [(10.0 * k, f"n{10 * k}") for k in range(len(kept))]


def test_repair_of_a_bag_without_messages_is_an_error(tmp_path, ms_mcap, capsys):
    bag = _cut_copy(ms_mcap, tmp_path / "cut", 30)
    assert main(["repair", str(bag)]) == 2
    assert "no complete message could be read" in capsys.readouterr().err
    assert not (tmp_path / "cut_repaired").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cut"]


def test_bag_records_gives_raw_messages_of_intact_and_cut_bags(tmp_path, ms_mcap, message_ends, capsys):
    """The layer below topic decoding (for other readers, e.g. IMU topics): raw CDR records."""
    full = list(bag_records(ms_mcap))
    assert len(full) == 14170 and capsys.readouterr().err == ""
    bag = _cut_copy(ms_mcap, tmp_path / "cut", int(message_ends[999]))
    part = list(bag_records(bag, ["segment_angles"]))
    assert part == full[:1000]
    assert part[0].topic == "/segment_angles" and part[0].msgtype == "sensor_msgs/msg/JointState"
    _warning(capsys)
    with pytest.raises(RecordingError, match="no topic /imu"):
        list(bag_records(bag, ["/imu"]))


def test_a_killed_bag_write_leaves_no_bag_or_a_complete_one(tmp_path, multispeed_csv):
    """--out-bag, convert and repair write into a temporary directory renamed when complete: a
    process killed while writing leaves no bag under the target name, never a cut one."""
    rec = read_recording(multispeed_csv)
    t0 = time.perf_counter()
    write_input_bag(rec, tmp_path / "ref", start_ns=START_NS)
    write_s = time.perf_counter() - t0
    inside = 0
    for i in range(8):
        target = tmp_path / f"b{i}"
        pid = os.fork()
        if pid == 0:  # the child: write the bag, then wait to be killed
            try:
                write_input_bag(rec, target, start_ns=START_NS)
                time.sleep(60)
            finally:
                os._exit(1)
        deadline = time.monotonic() + 10 * write_s
        while not list(tmp_path.glob(f".b{i}.*")) and time.monotonic() < deadline:
            pass  # until the child opens its bag writer (after serializing every message)
        time.sleep(write_s * i / 20)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        if target.exists():
            assert damage(target) == "" and len(read_bag(target)) == len(rec)
        staging = [d for d in tmp_path.glob(f".b{i}.*") if any(d.iterdir())]  # emptied after the rename
        assert not (staging and target.exists())
        inside += bool(staging)
    assert inside > 0, "no kill landed while the bag was being written"
