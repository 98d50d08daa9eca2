"""A recording in progress: serialized messages in, a rosbag2 bag (MCAP or sqlite3) out.

What ``pph_recorder`` does with each message it takes, without ROS: the stamp (a loop
message's sample time, n ms; the time ``/clock`` and ``/diagnostics`` carry; else the
recorder's clock), the drop of a loop sample already written on its topic (the lockstep
handshake offers sample 0 several times), the topic's connection on its first message
(as ``ros2 bag record`` does), the counts and the periodic flush that bounds what a killed
recorder loses.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2.errors import WriterError

from hexapod_vibration.analysis.bag_format import typestore
from hexapod_vibration.analysis.bag_writer import JazzyWriter, stamp_of_cdr
from hexapod_vibration.cdr import sample_index_of_cdr
from hexapod_vibration.core.loop.sample_set import SampleSet

FLUSH_PERIOD_S = 0.25
"""Longest time (s, wall) that written messages stay in memory before they are on disk."""
COMMIT_EVERY = 2000
"""sqlite3: messages per transaction at most (bounded loss and journal when killed)."""


class RecordingError(RuntimeError):
    """The bag cannot be created (the directory exists, the path is not writable)."""


class BagRecording:
    """An open bag and what has been written into it.

    Args:
        path: Bag directory to create (never overwritten).
        plugin: Storage (MCAP or sqlite3).
        custom_data: ``metadata.yaml`` ``custom_data`` entries.
        topics: Every topic that may be written.
        loop_topics: The topics whose messages carry ``sample:<n>``.

    Raises:
        RecordingError: The directory exists or the bag cannot be created.
    """

    def __init__(self, path: Path, plugin: StoragePlugin, custom_data: dict[str, str],
                 topics: Iterable[str], loop_topics: Iterable[str]) -> None:
        """Create and open the bag."""
        if path.exists():
            raise RecordingError(f"bag directory {path} exists already; refusing to overwrite "
                                 "it (remove it or choose another bag_path)")
        self.path = path
        self._writer: JazzyWriter | None = JazzyWriter(path, storage_plugin=plugin)
        for key, value in custom_data.items():
            self._writer.set_custom_data(key, value)
        try:
            self._writer.open()
        except (WriterError, OSError) as err:
            raise RecordingError(f"cannot create bag {path}: {err}") from err
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = dict.fromkeys(topics, 0)
        """Messages written, per topic."""
        self.duplicates: dict[str, int] = dict.fromkeys(loop_topics, 0)
        """Loop samples dropped as written already, per loop topic."""
        self._seen = {topic: SampleSet() for topic in self.duplicates}

    def last_sample(self, topic: str) -> int:
        """Highest sample index written on loop topic ``topic`` (-1: none yet)."""
        return self._seen[topic].highest

    @property
    def open(self) -> bool:
        """Whether the bag is still being written."""
        return self._writer is not None

    @property
    def flushed(self) -> int:
        """Messages on disk so far."""
        return 0 if self._writer is None else self._writer.flushed

    @property
    def total(self) -> int:
        """Messages written so far, all topics."""
        return sum(self.counts.values())

    def write(self, topic: str, msgtype: str, data: bytes, now_ns: Callable[[], int],
              offered_qos: Callable[[str], list]) -> bool:
        """Write one serialized message of ``topic``; False if it was not written.

        ``now_ns`` stamps a message that carries no time; ``offered_qos`` gives the QoS of
        the topic's publishers for its connection (asked on its first message).
        """
        if self._writer is None:
            return False
        stamp = self._stamp(topic, data, now_ns)
        if stamp is None:
            return False
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._writer.add_connection(topic, msgtype, typestore=typestore(),
                                                     offered_qos_profiles=offered_qos(topic))
            self._connections[topic] = connection
        self._writer.write(connection, stamp, data)
        self.counts[topic] += 1
        self._writer.flush_if_due(FLUSH_PERIOD_S, COMMIT_EVERY)
        return True

    def _stamp(self, topic: str, data: bytes, now_ns: Callable[[], int]) -> int | None:
        """Timestamp (ns) of a message; None for a loop sample already written."""
        seen = self._seen.get(topic)
        if seen is not None:
            sample = sample_index_of_cdr(data)
            repeated = None if sample is None else seen.add(sample)
            if repeated:
                self.duplicates[topic] += 1
                return None
            if repeated is not None:
                return sample * 1_000_000
        carried = stamp_of_cdr(topic, data)
        return carried if carried else now_ns()

    def flush_if_due(self) -> None:
        """Put what was written on disk if the flush period passed (also when idle)."""
        if self._writer is not None:
            self._writer.flush_if_due(FLUSH_PERIOD_S, COMMIT_EVERY)

    def close(self) -> str | None:
        """Close the bag (``metadata.yaml``); the per-topic counts as text, None if closed."""
        writer, self._writer = self._writer, None
        if writer is None:
            return None
        writer.close()
        return ", ".join(f"{name}: {n}" for name, n in self.counts.items() if n) or "none"
