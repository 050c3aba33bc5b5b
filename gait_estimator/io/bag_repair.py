"""Writing a complete, indexed copy of a bag from what is readable (``gait-estimator repair``),
as ``ros2 bag reindex`` rebuilds what a crash left.

The source is read as every command reads it (``bag.open_bag``: intact, or recovered by
``bag_recover``) and never modified. The copy is written with rosbags into a temporary
directory beside the output, its files fsynced, and renamed to the output at the end, so an
interrupted repair leaves no half-written bag under the output name.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..core.errors import GaitEstimatorError
from .bag import open_bag, typestore
from .bag_recover import storage_files

REPAIRED_SUFFIX = "_repaired"
BAG_VERSION = 8
"""rosbag2 metadata version written (ROS 2 Jazzy), as bag_write."""


@dataclass
class RepairResult:
    """What ``repair_bag`` wrote: output directory, storage, messages per topic, topics of
    types the type store does not know (not copied)."""

    out: Path
    storage: str
    counts: dict[str, int] = field(default_factory=dict)
    skipped_topics: list[str] = field(default_factory=list)
    recovered: str = ""

    @property
    def messages(self) -> int:
        return sum(self.counts.values())


def default_repair_path(bag: str | Path) -> Path:
    """``walk1`` -> ``walk1_repaired``; ``walk1/walk1_0.mcap`` -> ``walk1/walk1_0_repaired``."""
    p = Path(bag)
    name = p.stem if p.is_file() else p.name
    return p.with_name(name + REPAIRED_SUFFIX)


def repair_bag(bag: str | Path, out: str | Path | None = None) -> RepairResult:
    """Write every readable message of ``bag`` to a new bag directory ``out`` (default
    ``default_repair_path``), same storage as the source (mcap unless every file is .db3).

    Raises:
        GaitEstimatorError: ``out`` exists, its parent is missing, or nothing is readable
            (one line).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    src = Path(bag)
    target = Path(out) if out is not None else default_repair_path(src)
    if target.exists():
        raise GaitEstimatorError(f"{target}: already exists; repair writes a new bag directory")
    if not target.parent.is_dir():
        raise GaitEstimatorError(f"{target}: parent directory {target.parent} does not exist")
    if not src.exists():
        raise GaitEstimatorError(f"{src}: no such file or directory")
    files = storage_files(src) if src.is_dir() else [src]
    storage = "sqlite3" if files and all(f.suffix == ".db3" for f in files) else "mcap"
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    result = RepairResult(target, storage)
    work = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        staged = work / target.name
        with open_bag(src, all_topics=True) as reader:
            recovery = getattr(reader, "recovery", None)
            result.recovered = recovery.line() if recovery else ""
            with Writer(staged, version=BAG_VERSION, storage_plugin=plugin) as writer:
                conns = {}
                for c in reader.connections:
                    try:
                        conns[c.id] = writer.add_connection(
                            c.topic, c.msgtype, typestore=typestore(),
                            serialization_format=c.ext.serialization_format,
                            offered_qos_profiles=c.ext.offered_qos_profiles,
                        )
                    except Exception:  # a type the Jazzy type store does not know
                        result.skipped_topics.append(f"{c.topic} [{c.msgtype}]")
                for c, log_ns, data in reader.messages(connections=[c for c in reader.connections if c.id in conns]):
                    writer.write(conns[c.id], log_ns, data)
                    result.counts[c.topic] = result.counts.get(c.topic, 0) + 1
        for f in staged.iterdir():
            _fsync(f)
        os.rename(staged, target)
        _fsync(target.parent)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return result


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
