"""Opening a rosbag2 bag (closed, or a recording that was not closed) and reading it in order.

No ROS import (rosbags only). Every failure of an unreadable, truncated or corrupt bag
becomes a :class:`BagError` naming the bag.
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError
from rosbags.serde import SerdeError

from hexapod_vibration.analysis import recovery
from hexapod_vibration.analysis.bag_format import RECORDING_KEY, RECORDING_OPEN, STRUT_MSGTYPE

# What rosbags and its storage back-ends raise on unreadable, truncated or corrupt files.
_READ_ERRORS = (
    ReaderError,
    SerdeError,
    ArithmeticError,
    MemoryError,
    OSError,
    sqlite3.Error,
    struct.error,
    EOFError,
    ValueError,
    KeyError,
    IndexError,
    AssertionError,
)


class BagError(RuntimeError):
    """A bag that cannot be used: missing, truncated, corrupt or without the needed topics."""


def _bag_directory(bag_path: str | Path) -> Path:
    """The bag directory for ``bag_path`` (a bag directory or a file inside it)."""
    path = Path(bag_path)
    if not path.exists():
        raise BagError(f"bag not found: {path}")
    return path.parent if path.is_file() else path


def _metadata_custom_data(path: Path) -> dict[str, str] | None:
    """``custom_data`` of ``path/metadata.yaml`` (None if absent, {} if it has none)."""
    meta = path / "metadata.yaml"
    if not meta.is_file():
        return None
    try:
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        custom = info.get("custom_data") or {}
    except (yaml.YAMLError, OSError, KeyError, TypeError, AttributeError, UnicodeDecodeError):
        return {}   # rosbags' Reader reports what is wrong with it
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def open_reader(bag_path: str | Path) -> Any:
    """A reader of the bag (rosbags' Reader, or a recovery reader for an unfinished one).

    Every failure becomes a BagError naming the bag.
    """
    path = _bag_directory(bag_path)
    custom = _metadata_custom_data(path)
    if custom is None or custom.get(RECORDING_KEY) == RECORDING_OPEN:
        return recovery.open_unfinished(path, custom or {}, BagError)
    try:
        reader = Reader(path)
        reader.open()
    except _READ_ERRORS as err:
        raise BagError(
            f"cannot open bag {path} (truncated, corrupt or not a rosbag2 bag): {err}"
        ) from err
    return reader


def custom_data_of(reader: Any) -> dict[str, str]:
    """The bag's ``custom_data`` (rosbags' Reader or the recovery reader)."""
    custom = getattr(reader, "custom_data", None)
    if custom is None:
        storage = getattr(reader, "storage", None)
        custom = getattr(getattr(storage, "metadata", None), "custom", None)
    return {str(k): str(v) for k, v in (custom or {}).items()}


def iter_messages(
    reader: Any, connections: Sequence[Connection]
) -> Iterator[tuple[Connection, int, bytes]]:
    """Messages of ``connections`` in bag order; corruption becomes a BagError.

    An uncompressed MCAP bag is read sequentially (:func:`recovery.iter_mcap_messages`,
    bounded memory), in file order; anything else through the reader.
    """
    if not connections:
        return
    counts = dict.fromkeys((c.id for c in connections), 0)
    files = _sequential_mcap_files(reader)
    try:
        if files is None:
            for conn, timestamp, data in reader.messages(connections=connections):
                counts[conn.id] += 1
                yield conn, timestamp, data
        else:
            wanted = {(c.topic, c.msgtype): c for c in connections}
            for path in files:
                for topic, schema, timestamp, data in recovery.iter_mcap_messages(path):
                    conn = wanted.get((topic, schema))
                    if conn is not None:
                        counts[conn.id] += 1
                        yield conn, timestamp, data
    except _READ_ERRORS as err:
        raise BagError(f"bag {reader.path} is truncated or corrupt: {err!r}") from err
    for conn in connections:  # a damaged MCAP chunk can end the iteration silently
        if counts[conn.id] < conn.msgcount:
            raise BagError(
                f"bag {reader.path} is truncated or corrupt: read {counts[conn.id]} of the "
                f"{conn.msgcount} messages on {conn.topic} listed in its metadata.yaml"
            )


def _sequential_mcap_files(reader: Any) -> list[Path] | None:
    """The data files of a closed, uncompressed MCAP bag (None: read through rosbags)."""
    storage = getattr(reader, "storage", None)
    storages = getattr(storage, "storages", None)
    metadata = getattr(storage, "metadata", None)
    if not storages or getattr(metadata, "compression_mode", None):
        return None
    paths = [Path(getattr(s, "path", "")) for s in storages]
    return paths if all(p.suffix == ".mcap" and p.is_file() for p in paths) else None


def topics_summary(reader: Any) -> str:
    """``"topic (type), ..."`` of every topic of the bag, for error messages."""
    items = sorted(f"{name} ({info.msgtype})" for name, info in reader.topics.items())
    return ", ".join(items) or "no topics"


def strut_connections(reader: Any, topics: Sequence[str]) -> list[Connection]:
    """Connections of the wanted strut topics; BagError if one has the wrong type."""
    wanted = [c for c in reader.connections if c.topic in topics]
    for conn in wanted:
        if conn.msgtype != STRUT_MSGTYPE:
            raise BagError(
                f"bag {reader.path}: topic {conn.topic} has type {conn.msgtype}, "
                f"expected {STRUT_MSGTYPE}"
            )
    return wanted
