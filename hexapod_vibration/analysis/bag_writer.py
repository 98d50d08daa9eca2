"""Writing rosbag2 bags without ROS: the recorder's writer, and strut topics on the sample grid.

:func:`write_strut_bag` writes strut topics stamped on the sample grid (tests and tools).
:class:`JazzyWriter` (the recorder's) is rosbags' ``Writer`` with what rosbag2 Jazzy does
differently:

- files named ``<bag>_0.mcap`` / ``<bag>_0.db3`` (rosbags names them ``<bag>.mcap``);
- ``ros_distro: jazzy`` in ``metadata.yaml`` (and in the serialized metadata stored in the
  data file, and the sqlite3 ``schema`` table), not ``rosbags``;
- ``offered_qos_profiles`` as rosbag2 9 serializes them (rosbags does that already once it
  is given the profiles: :func:`qos_from_rclpy` converts rclpy's);
- a provisional ``metadata.yaml`` when the bag is opened (``custom_data`` marks it open,
  see :mod:`hexapod_vibration.analysis.recovery`), replaced by the final one on close;
- :meth:`JazzyWriter.flush_if_due`: MCAP chunks closed and flushed, sqlite3 transactions
  (write-ahead log) committed, at a bounded period and size, so that a killed writer
  leaves everything written before its last flush readable.
"""

from __future__ import annotations

import os
import sqlite3
import struct
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from hexapod_vibration.analysis.bag_files import BagError
from hexapod_vibration.analysis.bag_format import (
    BAG_VERSION,
    CLOCK_TOPIC,
    DIAGNOSTICS_TOPIC,
    RECORDING_KEY,
    RECORDING_OPEN,
    STORAGE_PLUGINS,
    STRUT_MSGTYPE,
    typestore,
)
from hexapod_vibration.contract import SAMPLE_RATE_HZ, STRUT_COUNT, STRUT_LABEL, sample_label

ROS_DISTRO = "jazzy"
_TIME = struct.Struct("<iI")


def _distro(metadata: str) -> str:
    return metadata.replace("ros_distro: rosbags", f"ros_distro: {ROS_DISTRO}")


class _JazzyMcap(McapWriter):
    """rosbags' MCAP storage, file ``<bag>_0.mcap``."""

    def __init__(self, path: Path, compression: Any) -> None:
        super().__init__(path, compression)
        target = path / f"{path.name}_0.mcap"
        self.path.rename(target)       # the open file handle follows the rename
        self.path = target

    def flush(self) -> None:
        """Close the pending chunk and hand the file's buffer to the OS."""
        if self.chunk.bio.tell():
            self.close_chunk()
        self.bio.flush()

    def close(self, version: int, metadata: str) -> None:
        """Write the summary and footer (metadata with ``ros_distro: jazzy``)."""
        super().close(version, _distro(metadata))


class _JazzySqlite(Sqlite3Writer):
    """rosbags' sqlite3 storage, file ``<bag>_0.db3``, write-ahead log, bounded commits."""

    def __init__(self, path: Path, compression: Any) -> None:
        super().__init__(path, compression)
        self.conn.commit()
        self.conn.close()
        target = path / f"{path.name}_0.db3"
        self.path.rename(target)
        self.path = target
        self.conn = sqlite3.connect(f"file:{self.path}", uri=True)
        self.conn.execute("PRAGMA journal_mode=WAL")
        self.conn.execute("UPDATE schema SET ros_distro = ?", (ROS_DISTRO,))
        self.conn.commit()
        self.cursor = self.conn.cursor()

    def flush(self) -> None:
        """Commit the pending transaction (to the write-ahead log)."""
        self.conn.commit()

    def close(self, version: int, metadata: str) -> None:
        """Store the metadata (``ros_distro: jazzy``), commit, checkpoint, close."""
        super().close(version, _distro(metadata))


class JazzyWriter(Writer):
    """rosbags ``Writer`` (version 9) writing bags as rosbag2 Jazzy does (module docstring)."""

    STORAGE_PLUGINS = {StoragePlugin.SQLITE3: _JazzySqlite, StoragePlugin.MCAP: _JazzyMcap}

    def __init__(self, path: Path | str, storage_plugin: StoragePlugin = StoragePlugin.MCAP
                 ) -> None:
        """Prepare a new bag at ``path`` (which must not exist)."""
        super().__init__(path, version=BAG_VERSION, storage_plugin=storage_plugin)
        self._last_flush = time.monotonic()
        self._unflushed = 0
        self.flushed = 0
        """Messages on disk (in the OS's hands) for sure: written before the last flush."""

    def open(self) -> None:
        """Create the bag and its provisional ``metadata.yaml``."""
        super().open()
        self._write_metadata({**self.custom_data, RECORDING_KEY: RECORDING_OPEN})

    def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
        """Write one message (see rosbags' ``Writer.write``)."""
        super().write(connection, timestamp, data)
        self._unflushed += 1

    def flush_if_due(self, period_s: float, max_messages: int) -> bool:
        """Put what was written on disk if ``period_s`` passed or ``max_messages`` are pending.

        Returns True if it flushed.
        """
        now = time.monotonic()
        if self.storage is None or not self._unflushed or (
                now - self._last_flush < period_s and self._unflushed < max_messages):
            return False
        self.storage.flush()
        self.flushed += self._unflushed
        self._last_flush, self._unflushed = now, 0
        return True

    def close(self) -> None:
        """Close the storage and write the final ``metadata.yaml`` (``ros_distro: jazzy``)."""
        super().close()
        meta = self.metapath
        text = _distro(meta.read_text(encoding="utf-8"))
        tmp = meta.with_suffix(".yaml.tmp")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, meta)

    def _write_metadata(self, custom_data: dict[str, str]) -> None:
        """The provisional metadata.yaml: no messages yet, ``custom_data`` marks it open."""
        assert self.storage is not None
        name = self.storage.path.name
        info = {
            "version": self.version,
            "storage_identifier": self.storage_plugin.name.lower(),
            "relative_file_paths": [name],
            "duration": {"nanoseconds": 0},
            "starting_time": {"nanoseconds_since_epoch": 0},
            "message_count": 0,
            "topics_with_message_count": [],
            "compression_format": "",
            "compression_mode": "",
            "files": [{"path": name, "starting_time": {"nanoseconds_since_epoch": 0},
                       "duration": {"nanoseconds": 0}, "message_count": 0}],
            "custom_data": custom_data,
            "ros_distro": ROS_DISTRO,
        }
        tmp = self.metapath.with_suffix(".yaml.tmp")
        tmp.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info},
                                      default_flow_style=False), encoding="utf-8")
        os.replace(tmp, self.metapath)


def _time(duration: Any) -> QosTime:
    ns = int(getattr(duration, "nanoseconds", 0))
    sec, nsec = divmod(ns, 1_000_000_000)
    return QosTime(sec, nsec)


def _enum(enum: Any, value: Any) -> Any:
    try:
        return enum(int(value))
    except (ValueError, TypeError):
        return enum.UNKNOWN


def qos_from_rclpy(profile: Any) -> Qos:
    """Rosbags ``Qos`` of an rclpy ``QoSProfile`` (as discovery reports a publisher's)."""
    return Qos(
        history=_enum(QosHistory, profile.history),
        depth=int(profile.depth),
        reliability=_enum(QosReliability, profile.reliability),
        durability=_enum(QosDurability, profile.durability),
        deadline=_time(profile.deadline),
        lifespan=_time(profile.lifespan),
        liveliness=_enum(QosLiveliness, profile.liveliness),
        liveliness_lease_duration=_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def stamp_of_cdr(topic: str, data: bytes) -> int:
    """Sim time (ns) a ``/clock`` or ``/diagnostics`` message carries; 0 if none or other.

    Both start with a ``builtin_interfaces/Time`` (the clock, the header stamp) right after
    the 4-byte CDR encapsulation header (little endian).
    """
    if topic not in (CLOCK_TOPIC, DIAGNOSTICS_TOPIC) or len(data) < 12 or data[1] != 1:
        return 0
    sec, nanosec = _TIME.unpack_from(data, 4)
    return max(sec, 0) * 1_000_000_000 + nanosec


def _strut_message(values: np.ndarray, index: int | None) -> Any:
    """A rosbags Float64MultiArray with the contract layout (index in band when given)."""
    store = typestore()
    dim_type = store.types["std_msgs/msg/MultiArrayDimension"]
    dims = [dim_type(label=STRUT_LABEL, size=STRUT_COUNT, stride=STRUT_COUNT)]
    if index is not None:
        dims.append(dim_type(label=sample_label(index), size=1, stride=1))
    layout = store.types["std_msgs/msg/MultiArrayLayout"](dim=dims, data_offset=0)
    return store.types[STRUT_MSGTYPE](layout=layout, data=np.asarray(values, np.float64))


def _timeline(
    series: Mapping[str, tuple[Iterable[int], np.ndarray]],
    sample_rate_hz: float,
    start_time_ns: int,
) -> list[tuple[int, str, int, np.ndarray]]:
    """``(timestamp_ns, topic, sample, values)`` of every message, in time order."""
    rows = []
    for topic, (indices, values) in series.items():
        index = np.asarray(list(indices), dtype=np.int64)
        array = np.asarray(values, dtype=np.float64).reshape(index.size, STRUT_COUNT)
        stamps = start_time_ns + np.rint(index * (1e9 / sample_rate_hz)).astype(np.int64)
        rows.extend(zip(stamps.tolist(), [topic] * index.size, index.tolist(), array, strict=True))
    rows.sort(key=lambda row: row[0])
    return rows


def write_strut_bag(
    path: str | Path,
    series: Mapping[str, tuple[Iterable[int], np.ndarray]],
    storage: Literal["mcap", "sqlite3"] = "mcap",
    sample_rate_hz: float = SAMPLE_RATE_HZ,
    in_band_index: bool = True,
    start_time_ns: int = 0,
) -> Path:
    """Write strut topics to a new rosbag2 bag, stamped on the sample grid.

    Message ``n`` of a topic is stamped ``start_time_ns + n / fs``; with ``in_band_index``
    it also carries ``sample:<n>`` in ``layout.dim[1]``, as the driver and controllers do.

    Args:
        path: Bag directory to create (must not exist).
        series: ``{topic: (sample indices (N,), values (N, 6))}``; indices may have gaps
            or repeats (to test the reader).
        storage: ``"mcap"`` or ``"sqlite3"``.
        sample_rate_hz: Loop rate (Hz) for the timestamps.
        in_band_index: Put the sample index in band.
        start_time_ns: Timestamp (ns) of sample 0.

    Returns:
        The bag directory.

    Raises:
        BagError: ``path`` exists already or cannot be written.
    """
    plugin = STORAGE_PLUGINS[storage]
    store = typestore()
    try:
        with Writer(path, version=BAG_VERSION, storage_plugin=plugin) as writer:
            conns = {
                topic: writer.add_connection(topic, STRUT_MSGTYPE, typestore=store)
                for topic in series
            }
            for stamp, topic, index, values in _timeline(series, sample_rate_hz, start_time_ns):
                msg = _strut_message(values, index if in_band_index else None)
                writer.write(conns[topic], stamp, store.serialize_cdr(msg, STRUT_MSGTYPE))
    except (WriterError, OSError) as err:
        raise BagError(f"cannot write bag {path}: {err}") from err
    return Path(path)
