"""A rosbag2 writer whose bags look like ROS 2 Jazzy's and survive a kill (no ROS import).

:class:`JazzyWriter` is rosbags' ``Writer`` with what rosbag2 Jazzy does differently:

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
from pathlib import Path
from typing import Any

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
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from hexapod_vibration.analysis.bag_io import (
    BAG_VERSION,
    CLOCK_TOPIC,
    DIAGNOSTICS_TOPIC,
    RECORDING_KEY,
    RECORDING_OPEN,
)

ROS_DISTRO = 'jazzy'
_TIME = struct.Struct('<iI')


def _distro(metadata: str) -> str:
    return metadata.replace('ros_distro: rosbags', f'ros_distro: {ROS_DISTRO}')


class _JazzyMcap(McapWriter):
    """rosbags' MCAP storage, file ``<bag>_0.mcap``."""

    def __init__(self, path: Path, compression: Any) -> None:
        super().__init__(path, compression)
        target = path / f'{path.name}_0.mcap'
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
        target = path / f'{path.name}_0.db3'
        self.path.rename(target)
        self.path = target
        self.conn = sqlite3.connect(f'file:{self.path}', uri=True)
        self.conn.execute('PRAGMA journal_mode=WAL')
        self.conn.execute('UPDATE schema SET ros_distro = ?', (ROS_DISTRO,))
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
        text = _distro(meta.read_text(encoding='utf-8'))
        tmp = meta.with_suffix('.yaml.tmp')
        tmp.write_text(text, encoding='utf-8')
        os.replace(tmp, meta)

    def _write_metadata(self, custom_data: dict[str, str]) -> None:
        """The provisional metadata.yaml: no messages yet, ``custom_data`` marks it open."""
        assert self.storage is not None
        name = self.storage.path.name
        info = {
            'version': self.version,
            'storage_identifier': self.storage_plugin.name.lower(),
            'relative_file_paths': [name],
            'duration': {'nanoseconds': 0},
            'starting_time': {'nanoseconds_since_epoch': 0},
            'message_count': 0,
            'topics_with_message_count': [],
            'compression_format': '',
            'compression_mode': '',
            'files': [{'path': name, 'starting_time': {'nanoseconds_since_epoch': 0},
                       'duration': {'nanoseconds': 0}, 'message_count': 0}],
            'custom_data': custom_data,
            'ros_distro': ROS_DISTRO,
        }
        tmp = self.metapath.with_suffix('.yaml.tmp')
        tmp.write_text(yaml.safe_dump({'rosbag2_bagfile_information': info},
                                      default_flow_style=False), encoding='utf-8')
        os.replace(tmp, self.metapath)


def _time(duration: Any) -> QosTime:
    ns = int(getattr(duration, 'nanoseconds', 0))
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
