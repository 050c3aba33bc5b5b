"""Writing a complete, indexed copy of a bag from what is readable (``gait-estimator repair``),
as ``ros2 bag reindex`` rebuilds what a crash left.

The source is read as every command reads it (``bag.open_bag``: intact, or recovered by
``bag_recover``) and never modified. The copy is written as every bag is
(``bag_write.staged_writer``): into a temporary directory beside the output, fsynced, renamed
to the output at the end, so an interrupted repair leaves no half-written bag under its name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..core.errors import GaitEstimatorError
from .bag import open_bag, typestore
from .bag_recover import storage_files
from .bag_write import staged_writer

REPAIRED_SUFFIX = "_repaired"


@dataclass
class RepairResult:
    """What ``repair_bag`` wrote: output directory, storage, messages per topic, topics not
    copied (a type the type store does not know, without a definition in the bag)."""

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
    src = Path(bag)
    target = Path(out) if out is not None else default_repair_path(src)
    if target.exists():
        raise GaitEstimatorError(f"{target}: already exists; repair writes a new bag directory")
    if not target.parent.is_dir():
        raise GaitEstimatorError(f"{target}: parent directory {target.parent} does not exist")
    if not src.exists():
        raise GaitEstimatorError(f"{src}: no such file or directory")
    files = storage_files(src)
    storage = "sqlite3" if files and all(f.suffix == ".db3" for f in files) else "mcap"
    result = RepairResult(target, storage)
    with open_bag(src, all_topics=True) as reader, staged_writer(target, storage) as writer:
        recovery = getattr(reader, "recovery", None)
        result.recovered = recovery.line() if recovery else ""
        conns = {}
        for c in reader.connections:
            if (conn := _add_connection(writer, c)) is None:
                result.skipped_topics.append(f"{c.topic} [{c.msgtype}]")
            else:
                conns[c.id] = conn
        for c, log_ns, data in reader.messages(connections=[c for c in reader.connections if c.id in conns]):
            writer.write(conns[c.id], log_ns, data)
            result.counts[c.topic] = result.counts.get(c.topic, 0) + 1
    return result


UNKNOWN_RIHS01 = "RIHS01_" + "0" * 64
"""Type hash written with a recorded definition that gives none and cannot be hashed."""


def _add_connection(writer: Any, c: Any) -> Any:
    """Add the source connection ``c`` to ``writer``: with the Jazzy type store's definition,
    or, for a type it does not know (a custom message), with the definition recorded in the
    source bag, as ``ros2 bag reindex`` keeps it. None if neither is there."""
    kw = {"serialization_format": c.ext.serialization_format, "offered_qos_profiles": c.ext.offered_qos_profiles}
    try:
        return writer.add_connection(c.topic, c.msgtype, typestore=typestore(), **kw)
    except Exception:  # a type the Jazzy type store does not know
        recorded = getattr(c.msgdef, "data", "")
        if not recorded:
            return None
        rihs01 = c.digest or _rihs01(c.msgtype, c.msgdef)
        return writer.add_connection(c.topic, c.msgtype, msgdef=recorded, rihs01=rihs01, **kw)


def _rihs01(msgtype: str, msgdef: Any) -> str:
    """The type hash of a recorded .msg definition (a cut mcap gives the definition without
    it), as rosbags' AnyReader computes it to check a bag's types."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if msgdef.format != MessageDefinitionFormat.MSG:
        return UNKNOWN_RIHS01
    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(msgdef.data, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception:  # a definition rosbags cannot parse
        return UNKNOWN_RIHS01
