"""Read and write rosbag2 bags of the contract topics, with every value placed on its sample.

Uses ``rosbags`` only (no rclpy import), so the analysis runs on any machine with numpy.
Reads MCAP and sqlite3 bags, written by ``ros2 bag record``, by the package's
``pph_recorder`` or by :func:`write_strut_bag`.

Sample placement: a message whose ``layout.dim[1]`` is ``sample:<n>`` is placed on sample
``n`` ("in-band"). A topic whose messages carry no index (another publisher) falls back to
the bag timestamps: ``n = round((t - t0) * fs)`` with ``t0`` the earliest timestamp of the
strut topics read, so that the topics stay aligned with each other ("timestamp").
Values are sorted by sample; repeated samples keep the first message received and are
counted; gaps are counted, never interpolated.
"""

from __future__ import annotations

import sqlite3
import struct
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.errors import ReaderError, WriterError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from hexapod_vibration.contract import (
    SAMPLE_RATE_HZ,
    STRUT_COUNT,
    STRUT_LABEL,
    InvalidStrutMessage,
    parse_sample_label,
    sample_label,
)

STRUT_TOPICS: tuple[str, ...] = (
    '/pph/accel',
    '/pph/eddy',
    '/pph/notch_command',
    '/pph/pointing_command',
    '/pph/actuator_force',
)
"""The contract's ``std_msgs/Float64MultiArray`` topics, six values each."""

ACCEL_TOPIC = '/pph/accel'
STRUT_MSGTYPE = 'std_msgs/msg/Float64MultiArray'
CLOCK_TOPIC = '/clock'
CLOCK_MSGTYPE = 'rosgraph_msgs/msg/Clock'
PARAMETER_EVENTS_TOPIC = '/parameter_events'
PARAMETER_EVENT_MSGTYPE = 'rcl_interfaces/msg/ParameterEvent'

TYPESTORE_NAME = Stores.ROS2_JAZZY
"""rosbags typestore matching ROS 2 Jazzy's message definitions and type hashes."""

BAG_VERSION = 9
"""rosbag2 metadata version written (the one ROS 2 Jazzy writes)."""

STORAGE_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
"""rosbag2 storage plugins by their ``ros2 bag`` name (the recorder's ``storage``)."""

IndexSource = Literal['in-band', 'timestamp']

_TYPESTORE: Typestore | None = None

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


@dataclass(frozen=True)
class StrutSeries:
    """One ``/pph/*`` topic of a bag, one row per sample.

    Attributes:
        topic: Topic name.
        sample_index: Loop sample index of each row, int64 (N,), strictly increasing.
        values: Six values per row in strut order 1..6, SI units, float64 (N, 6).
        timestamp_ns: Bag timestamp of each row's message (ns), int64 (N,).
        missing_samples: Samples absent between the first and the last row.
        duplicate_samples: Messages dropped because their sample was already present.
        index_source: ``"in-band"`` (``sample:<n>`` labels) or ``"timestamp"``.
        invalid_messages: Messages skipped as unusable (wrong length, non-finite values,
            garbled label, or no index on a topic whose other messages have one).
    """

    topic: str
    sample_index: np.ndarray
    values: np.ndarray
    timestamp_ns: np.ndarray
    missing_samples: int
    duplicate_samples: int
    index_source: IndexSource
    invalid_messages: int = 0

    def __len__(self) -> int:
        """Number of samples (rows)."""
        return int(self.sample_index.shape[0])


@dataclass
class _RawTopic:
    """Messages of one strut topic as read, in bag order."""

    timestamps: list[int]
    values: list[np.ndarray]
    labels: list[int | None]
    invalid: int = 0


def typestore() -> Typestore:
    """The shared rosbags typestore for ROS 2 Jazzy (built once)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(TYPESTORE_NAME)
    return _TYPESTORE


# --------------------------------------------------------------------------- reading


def _bag_directory(bag_path: str | Path) -> Path:
    """The bag directory for ``bag_path`` (a bag directory or a file inside one)."""
    path = Path(bag_path)
    if not path.exists():
        raise BagError(f'bag not found: {path}')
    if path.is_file():
        path = path.parent
    if not (path / 'metadata.yaml').is_file():
        raise BagError(
            f'{path} is not a readable rosbag2 bag: it has no metadata.yaml (not a bag, or a '
            f'recording that was not closed cleanly: `ros2 bag reindex {path}` can rebuild it)'
        )
    return path


def _open_reader(bag_path: str | Path) -> Reader:
    """Open a rosbags Reader, turning every failure into a BagError naming the bag."""
    path = _bag_directory(bag_path)
    try:
        reader = Reader(path)
        reader.open()
    except _READ_ERRORS as err:
        raise BagError(
            f'cannot open bag {path} (truncated, corrupt or not a rosbag2 bag): {err}'
        ) from err
    return reader


def _iter_messages(
    reader: Reader, connections: Sequence[Connection]
) -> Iterator[tuple[Connection, int, bytes]]:
    """Messages of ``connections`` in bag order; corruption becomes a BagError."""
    if not connections:
        return
    counts = dict.fromkeys((c.id for c in connections), 0)
    try:
        for conn, timestamp, data in reader.messages(connections=connections):
            counts[conn.id] += 1
            yield conn, timestamp, data
    except _READ_ERRORS as err:
        raise BagError(f'bag {reader.path} is truncated or corrupt: {err!r}') from err
    for conn in connections:  # a damaged MCAP chunk can end the iteration silently
        if counts[conn.id] < conn.msgcount:
            raise BagError(
                f'bag {reader.path} is truncated or corrupt: read {counts[conn.id]} of the '
                f'{conn.msgcount} messages on {conn.topic} listed in its metadata.yaml'
            )


def _topics_summary(reader: Reader) -> str:
    """``"topic (type), ..."`` of every topic of the bag, for error messages."""
    items = sorted(f'{name} ({info.msgtype})' for name, info in reader.topics.items())
    return ', '.join(items) or 'no topics'


def _check_strut_connections(reader: Reader, topics: Sequence[str]) -> list[Connection]:
    """Connections of the wanted strut topics; BagError if one has the wrong type."""
    wanted = [c for c in reader.connections if c.topic in topics]
    for conn in wanted:
        if conn.msgtype != STRUT_MSGTYPE:
            raise BagError(
                f'bag {reader.path}: topic {conn.topic} has type {conn.msgtype}, '
                f'expected {STRUT_MSGTYPE}'
            )
    return wanted


def _parse_strut(msg: Any) -> tuple[np.ndarray, int | None]:
    """Values and in-band index of a deserialized Float64MultiArray (rosbags object)."""
    values = np.asarray(msg.data, dtype=np.float64)
    if values.shape != (STRUT_COUNT,):
        raise InvalidStrutMessage(f'expected {STRUT_COUNT} strut values, got {values.size}')
    if not np.isfinite(values).all():
        raise InvalidStrutMessage(f'non-finite strut value in {values.tolist()}')
    dims = msg.layout.dim
    if len(dims) < 2:
        return values, None
    return values, parse_sample_label(dims[1].label)


def _collect_strut_messages(
    reader: Reader, connections: Sequence[Connection]
) -> dict[str, _RawTopic]:
    """Deserialize the strut messages, grouped by topic, skipping unusable ones."""
    store = typestore()
    raw: dict[str, _RawTopic] = {c.topic: _RawTopic([], [], []) for c in connections}
    for conn, timestamp, data in _iter_messages(reader, connections):
        topic = raw[conn.topic]
        try:
            values, label = _parse_strut(store.deserialize_cdr(data, STRUT_MSGTYPE))
        except InvalidStrutMessage:
            topic.invalid += 1
            continue
        except _READ_ERRORS as err:
            raise BagError(
                f'bag {reader.path}: undecodable message on {conn.topic}: {err!r}'
            ) from err
        topic.timestamps.append(timestamp)
        topic.values.append(values)
        topic.labels.append(label)
    return raw


def _index_from_labels(raw: _RawTopic) -> tuple[np.ndarray, np.ndarray, int]:
    """In-band indices; messages without one are dropped. Returns (rows, index, dropped)."""
    rows = np.array([i for i, label in enumerate(raw.labels) if label is not None], np.int64)
    index = np.array([raw.labels[i] for i in rows], dtype=np.int64)
    return rows, index, len(raw.labels) - rows.size


def _index_from_timestamps(timestamps: np.ndarray, t0_ns: int, sample_rate_hz: float) -> np.ndarray:
    """``round((t - t0) * fs)`` on the bag timestamps (ns), as int64."""
    return np.rint((timestamps - t0_ns) * (sample_rate_hz * 1e-9)).astype(np.int64)


def _build_series(topic: str, raw: _RawTopic, t0_ns: int, sample_rate_hz: float) -> StrutSeries:
    """Place the messages of one topic on their samples: sort, drop duplicates, count gaps."""
    timestamps = np.asarray(raw.timestamps, dtype=np.int64)
    values = np.asarray(raw.values, dtype=np.float64).reshape(-1, STRUT_COUNT)
    invalid = raw.invalid
    if any(label is not None for label in raw.labels):
        source: IndexSource = 'in-band'
        rows, index, dropped = _index_from_labels(raw)
        timestamps, values, invalid = timestamps[rows], values[rows], invalid + dropped
    else:
        source = 'timestamp'
        index = _index_from_timestamps(timestamps, t0_ns, sample_rate_hz)
    order = np.argsort(index, kind='stable')  # stable: the first received copy comes first
    index, timestamps, values = index[order], timestamps[order], values[order]
    keep = np.ones(index.shape, dtype=bool)
    keep[1:] = index[1:] != index[:-1]
    index, timestamps, values = index[keep], timestamps[keep], values[keep]
    span = int(index[-1] - index[0] + 1) if index.size else 0
    return StrutSeries(
        topic=topic,
        sample_index=index,
        values=values,
        timestamp_ns=timestamps,
        missing_samples=span - int(index.size),
        duplicate_samples=int((~keep).sum()),
        index_source=source,
        invalid_messages=invalid,
    )


def read_strut_topics(
    bag_path: str | Path,
    topics: Sequence[str] = STRUT_TOPICS,
    sample_rate_hz: float = SAMPLE_RATE_HZ,
    required: Sequence[str] | None = None,
) -> dict[str, StrutSeries]:
    """Read the ``/pph/*`` topics of a bag, each value placed on its loop sample.

    Args:
        bag_path: Bag directory (or a file inside it), MCAP or sqlite3.
        topics: Strut topics to read; those absent from the bag are left out of the result.
        sample_rate_hz: Loop rate (Hz) for topics placed by timestamp.
        required: Topics that must be present; default ``("/pph/accel",)`` when it is
            among ``topics``.

    Returns:
        ``{topic: StrutSeries}`` for the requested topics present in the bag.

    Raises:
        BagError: Missing, truncated or corrupt bag; a required topic is absent (the
            message lists the bag's topics); a topic has another type than
            ``std_msgs/msg/Float64MultiArray``.
    """
    if required is None:
        required = (ACCEL_TOPIC,) if ACCEL_TOPIC in topics else ()
    reader = _open_reader(bag_path)
    try:
        absent = [t for t in required if t not in reader.topics]
        if absent:
            raise BagError(
                f'bag {reader.path} has no {", ".join(absent)}; its topics: '
                f'{_topics_summary(reader)}'
            )
        raw = _collect_strut_messages(reader, _check_strut_connections(reader, topics))
    finally:
        reader.close()
    starts = [min(r.timestamps) for r in raw.values() if r.timestamps]
    t0_ns = min(starts) if starts else 0
    return {topic: _build_series(topic, raw[topic], t0_ns, sample_rate_hz) for topic in raw}


def _read_topic(bag_path: str | Path, topic: str, msgtype: str) -> list[tuple[int, Any]]:
    """``(timestamp_ns, message)`` of one topic, empty if the bag does not have it."""
    reader = _open_reader(bag_path)
    try:
        connections = [c for c in reader.connections if c.topic == topic]
        for conn in connections:
            if conn.msgtype != msgtype:
                raise BagError(
                    f'bag {reader.path}: topic {topic} has type {conn.msgtype}, expected {msgtype}'
                )
        store = typestore()
        return [
            (timestamp, store.deserialize_cdr(data, msgtype))
            for _, timestamp, data in _iter_messages(reader, connections)
        ]
    except _READ_ERRORS as err:
        raise BagError(f'bag {reader.path}: undecodable message on {topic}: {err!r}') from err
    finally:
        reader.close()


def read_clock(bag_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``/clock`` of a bag: (bag timestamps (ns), clock times (ns)), int64 arrays.

    Both are empty when ``/clock`` was not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    records = _read_topic(bag_path, CLOCK_TOPIC, CLOCK_MSGTYPE)
    stamps = np.array([t for t, _ in records], dtype=np.int64)
    clock = np.array(
        [m.clock.sec * 1_000_000_000 + m.clock.nanosec for _, m in records], dtype=np.int64
    )
    return stamps, clock


# ParameterValue.type -> field holding the value (rcl_interfaces/msg/ParameterType).
_PARAMETER_FIELDS = {
    1: 'bool_value',
    2: 'integer_value',
    3: 'double_value',
    4: 'string_value',
    5: 'byte_array_value',
    6: 'bool_array_value',
    7: 'integer_array_value',
    8: 'double_array_value',
    9: 'string_array_value',
}


def _parameter_value(value: Any) -> Any:
    """Python value of an ``rcl_interfaces/msg/ParameterValue`` (None when not set)."""
    field = _PARAMETER_FIELDS.get(int(value.type))
    if field is None:
        return None
    result = getattr(value, field)
    return result.tolist() if isinstance(result, np.ndarray) else result


def read_parameter_events(
    bag_path: str | Path, node: str = '/notch_controller', name: str = 'enabled'
) -> list[tuple[int, Any]]:
    """Values taken by one parameter, from ``/parameter_events`` if it was recorded.

    Args:
        bag_path: Bag directory (or a file inside it).
        node: Fully qualified node name, e.g. ``"/notch_controller"``.
        name: Parameter name.

    Returns:
        ``[(bag timestamp (ns), value), ...]`` in bag order, the declaration (new parameter)
        included; empty if ``/parameter_events`` was not recorded or never mentions it.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    events = []
    for timestamp, event in _read_topic(bag_path, PARAMETER_EVENTS_TOPIC, PARAMETER_EVENT_MSGTYPE):
        if event.node != node:
            continue
        for param in (*event.new_parameters, *event.changed_parameters):
            if param.name == name:
                events.append((timestamp, _parameter_value(param.value)))
    return events


# --------------------------------------------------------------------------- writing


def _strut_message(values: np.ndarray, index: int | None) -> Any:
    """A rosbags Float64MultiArray with the contract layout (index in band when given)."""
    store = typestore()
    dim_type = store.types['std_msgs/msg/MultiArrayDimension']
    dims = [dim_type(label=STRUT_LABEL, size=STRUT_COUNT, stride=STRUT_COUNT)]
    if index is not None:
        dims.append(dim_type(label=sample_label(index), size=1, stride=1))
    layout = store.types['std_msgs/msg/MultiArrayLayout'](dim=dims, data_offset=0)
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
    storage: Literal['mcap', 'sqlite3'] = 'mcap',
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
        raise BagError(f'cannot write bag {path}: {err}') from err
    return Path(path)


# --------------------------------------------------------------------------- other topics

DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTICS_MSGTYPE = 'diagnostic_msgs/msg/DiagnosticArray'
WEIGHTS_TOPIC = '/pph/notch_weights'


def read_diagnostics(bag_path: str | Path, name_prefix: str = '') -> list[tuple[int, str, dict]]:
    """Statuses on ``/diagnostics``: ``[(bag timestamp (ns), status name, {key: value})]``.

    Only statuses whose name starts with ``name_prefix``; empty if not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    statuses = []
    for timestamp, array in _read_topic(bag_path, DIAGNOSTICS_TOPIC, DIAGNOSTICS_MSGTYPE):
        for status in array.status:
            if status.name.startswith(name_prefix):
                values = {kv.key: kv.value for kv in status.values}
                statuses.append((timestamp, status.name, values))
    return statuses


def read_notch_weights(bag_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Notch weights from ``/pph/notch_weights``: (sample index (N,), a/b (N, T, 6, 2)).

    Messages whose tone count differs from the last message's (tones changed) are skipped.
    Both arrays are empty if the topic was not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    records = _read_topic(bag_path, WEIGHTS_TOPIC, STRUT_MSGTYPE)
    rows, index = [], []
    tones = int(records[-1][1].layout.dim[0].size) if records else 0
    for _, msg in records:
        dims = msg.layout.dim
        if len(dims) < 4 or int(dims[0].size) != tones or msg.data.size != tones * 12:
            continue
        try:
            sample = parse_sample_label(dims[3].label)
        except InvalidStrutMessage:
            continue
        index.append(sample)
        rows.append(np.asarray(msg.data, dtype=float).reshape(tones, 6, 2))
    if not rows:
        return np.zeros(0, dtype=np.int64), np.zeros((0, tones, 6, 2))
    return np.asarray(index, dtype=np.int64), np.stack(rows)
