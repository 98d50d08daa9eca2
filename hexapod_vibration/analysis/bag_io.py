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

import dataclasses
import sqlite3
import struct
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from rosbags.interfaces import Connection
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.errors import ReaderError, WriterError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from hexapod_vibration.analysis import recovery
from hexapod_vibration.cdr import (
    LITTLE_ENDIAN_CDR,
    MAX_BAG_SAMPLE_INDEX,
    decode_float64_array,
)
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_SENSITIVITY_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
    SAMPLE_RATE_HZ,
    SENSITIVITY_ROWS_PREFIX,
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
DIAGNOSTICS_TOPIC = '/diagnostics'
DIAGNOSTICS_MSGTYPE = 'diagnostic_msgs/msg/DiagnosticArray'
WEIGHTS_TOPIC = '/pph/notch_weights'
FREQUENCY_TOPICS: tuple[str, ...] = (
    REFERENCE_FREQUENCY_TOPIC, DISTURBANCE_FREQUENCIES_TOPIC, NOTCH_FREQUENCIES_TOPIC)
"""Frequencies (Hz) per sample: any number of values, ``sample:<n>`` in ``layout.dim[1]``."""
SENSITIVITY_TOPIC = NOTCH_SENSITIVITY_TOPIC

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


def typestore() -> Typestore:
    """The shared rosbags typestore for ROS 2 Jazzy (built once)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(TYPESTORE_NAME)
    return _TYPESTORE


# --------------------------------------------------------------------------- opening

RECORDING_KEY = 'hexapod_vibration.recording'
"""``custom_data`` key of the provisional ``metadata.yaml`` written when a recording starts;
the final one (written when the bag is closed) does not have it."""
RECORDING_OPEN = 'open'
RUN_RECORD_KEY = 'hexapod_vibration.run'
"""``custom_data`` key holding the experiment's run record (JSON), see analysis.report."""


def _bag_directory(bag_path: str | Path) -> Path:
    """The bag directory for ``bag_path`` (a bag directory or a file inside it)."""
    path = Path(bag_path)
    if not path.exists():
        raise BagError(f'bag not found: {path}')
    return path.parent if path.is_file() else path


def _metadata_custom_data(path: Path) -> dict[str, str] | None:
    """``custom_data`` of ``path/metadata.yaml`` (None if absent, {} if it has none)."""
    meta = path / 'metadata.yaml'
    if not meta.is_file():
        return None
    try:
        info = yaml.safe_load(meta.read_text(encoding='utf-8'))['rosbag2_bagfile_information']
        custom = info.get('custom_data') or {}
    except (yaml.YAMLError, OSError, KeyError, TypeError, AttributeError, UnicodeDecodeError):
        return {}   # rosbags' Reader reports what is wrong with it
    return {str(k): str(v) for k, v in custom.items()} if isinstance(custom, dict) else {}


def _open_reader(bag_path: str | Path) -> Any:
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
            f'cannot open bag {path} (truncated, corrupt or not a rosbag2 bag): {err}'
        ) from err
    return reader


def _custom_data(reader: Any) -> dict[str, str]:
    """The bag's ``custom_data`` (rosbags' Reader or the recovery reader)."""
    custom = getattr(reader, 'custom_data', None)
    if custom is None:
        storage = getattr(reader, 'storage', None)
        custom = getattr(getattr(storage, 'metadata', None), 'custom', None)
    return {str(k): str(v) for k, v in (custom or {}).items()}


def read_custom_data(bag_path: str | Path) -> dict[str, str]:
    """``custom_data`` of a bag's metadata (empty if it has none)."""
    return _metadata_custom_data(_bag_directory(bag_path)) or {}


def _iter_messages(
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
        raise BagError(f'bag {reader.path} is truncated or corrupt: {err!r}') from err
    for conn in connections:  # a damaged MCAP chunk can end the iteration silently
        if counts[conn.id] < conn.msgcount:
            raise BagError(
                f'bag {reader.path} is truncated or corrupt: read {counts[conn.id]} of the '
                f'{conn.msgcount} messages on {conn.topic} listed in its metadata.yaml'
            )


def _sequential_mcap_files(reader: Any) -> list[Path] | None:
    """The data files of a closed, uncompressed MCAP bag (None: read through rosbags)."""
    storage = getattr(reader, 'storage', None)
    storages = getattr(storage, 'storages', None)
    metadata = getattr(storage, 'metadata', None)
    if not storages or getattr(metadata, 'compression_mode', None):
        return None
    paths = [Path(getattr(s, 'path', '')) for s in storages]
    return paths if all(p.suffix == '.mcap' and p.is_file() for p in paths) else None


def _topics_summary(reader: Any) -> str:
    """``"topic (type), ..."`` of every topic of the bag, for error messages."""
    items = sorted(f'{name} ({info.msgtype})' for name, info in reader.topics.items())
    return ', '.join(items) or 'no topics'


def _check_strut_connections(reader: Any, topics: Sequence[str]) -> list[Connection]:
    """Connections of the wanted strut topics; BagError if one has the wrong type."""
    wanted = [c for c in reader.connections if c.topic in topics]
    for conn in wanted:
        if conn.msgtype != STRUT_MSGTYPE:
            raise BagError(
                f'bag {reader.path}: topic {conn.topic} has type {conn.msgtype}, '
                f'expected {STRUT_MSGTYPE}'
            )
    return wanted


@dataclass(frozen=True)
class StrutSeries:
    """One ``/pph/*`` topic of a bag, one row per kept sample.

    Attributes:
        topic: Topic name.
        sample_index: Loop sample index of each row, int64 (N,), strictly increasing.
        values: Values per row, float64 (N, 6) in strut order 1..6, SI units; (N, m) when
            the topic was read with a projection (:class:`Keep`).
        timestamp_ns: Bag timestamp of each row's message (ns), int64 (N,); empty when the
            topic was read without timestamps.
        missing_samples: Samples absent between the first and the last sample received.
        duplicate_samples: Messages dropped because their sample was already present.
        index_source: ``"in-band"`` (``sample:<n>`` labels) or ``"timestamp"``.
        invalid_messages: Messages skipped as unusable (undecodable bytes, wrong length,
            non-finite values, garbled or out-of-range label, or no index on a topic whose
            other messages have one).
        samples: Distinct samples received (all of them, also when rows are decimated).
        first_sample: First sample received (-1 if none).
        last_sample: Last sample received (-1 if none).
    """

    topic: str
    sample_index: np.ndarray
    values: np.ndarray
    timestamp_ns: np.ndarray
    missing_samples: int
    duplicate_samples: int
    index_source: IndexSource
    invalid_messages: int = 0
    samples: int = -1
    first_sample: int = -1
    last_sample: int = -1

    def __len__(self) -> int:
        """Number of distinct samples received (rows, unless the rows were decimated)."""
        return int(self.samples if self.samples >= 0 else self.sample_index.shape[0])

    def missing_in(self, run_samples: int) -> int:
        """Samples of the run ``[0, run_samples)`` that this topic does not have."""
        return max(int(run_samples) - len(self), 0)


@dataclass(frozen=True)
class Keep:
    """What to keep of a strut topic while streaming a bag (bounded memory).

    Attributes:
        columns: ``(6, m)`` matrix: rows keep ``values @ columns`` (m values, e.g. the
            top plate's z acceleration) instead of the six values; None keeps the six.
        every: Keep values only of samples ``n`` with ``n % every == 0`` (in-band topics;
            the sample accounting still covers every sample).
        timestamps: Keep the bag timestamps of the kept rows.
        block: If > 0, keep per block of ``block`` samples (in-band topics) the mean and
            the RMS deviation from it of each (projected) value instead of the rows:
            ``values`` is then ``(blocks, 2 m)`` (means, then RMS), ``sample_index`` the
            blocks' first samples (for plots of long runs; duplicates count twice).
    """

    columns: np.ndarray | None = None
    every: int = 1
    timestamps: bool = True
    block: int = 0


KEEP_ALL = Keep()

_BLOCK = 4096


class _SampleSet:
    """Set of sample indices as a bitmap in 64 Ki-sample chunks (1 bit per sample)."""

    CHUNK = 1 << 16

    def __init__(self) -> None:
        self._chunks: dict[int, bytearray] = {}
        self.count = 0
        self.first = -1
        self.last = -1

    def add(self, n: int) -> bool:
        """Add ``n``; True if it was there already."""
        chunk, offset = divmod(n, self.CHUNK)
        bits = self._chunks.get(chunk)
        if bits is None:
            bits = self._chunks[chunk] = bytearray(self.CHUNK // 8)
        byte, bit = divmod(offset, 8)
        if bits[byte] >> bit & 1:
            return True
        bits[byte] |= 1 << bit
        self.count += 1
        self.first = n if self.first < 0 else min(self.first, n)
        self.last = max(self.last, n)
        return False


class _TopicStream:
    """Messages of one strut topic, decoded as they stream by into compact numpy blocks.

    In-band samples are accounted for in a bitmap (1 bit per sample); a row (label,
    timestamp and what :class:`Keep` keeps of the values) is stored only for the first
    copy of a sample that the Keep asks for, so a topic read for its accounting only costs
    1 bit per sample.
    """

    def __init__(self, topic: str, keep: Keep) -> None:
        self.topic, self.keep = topic, keep
        self.invalid = 0
        self.duplicates = 0
        self._set = _SampleSet()
        self._labels: list[np.ndarray] = []   # stored rows' labels (-1: none)
        self._stamps: list[np.ndarray] = []
        self._values: list[np.ndarray] = []
        self._buf_label = np.empty(_BLOCK, np.int64)
        self._buf_stamp = np.empty(_BLOCK, np.int64)
        self._buf_values = np.empty((_BLOCK, STRUT_COUNT))
        self._n = 0
        self.first_timestamp: int | None = None
        self._blocks: dict[int, np.ndarray] = {}   # block -> [count, sums (m), squares (m)]
        width = STRUT_COUNT if keep.columns is None else int(keep.columns.shape[1])
        self._rows_wanted = keep.block > 0 or width > 0 or keep.timestamps

    def add(self, timestamp: int, data: bytes | memoryview) -> None:
        """Decode one serialized message; an unusable one is counted and skipped."""
        try:
            values, label = decode_strut_message(data)
        except InvalidStrutMessage:
            self.invalid += 1
            return
        if self.first_timestamp is None or timestamp < self.first_timestamp:
            self.first_timestamp = timestamp
        if label is not None:
            if self._set.add(label):
                self.duplicates += 1
                return
            every = max(1, self.keep.every)
            if not self._rows_wanted or (self.keep.block <= 0 and label % every):
                return
        k = self._n
        self._buf_label[k] = -1 if label is None else label
        self._buf_stamp[k] = timestamp
        self._buf_values[k] = values
        self._n += 1
        if self._n == _BLOCK:
            self._flush()

    def _flush(self) -> None:
        n = self._n
        if not n:
            return
        labels = self._buf_label[:n].copy()
        stamps = self._buf_stamp[:n].copy()
        rows = self._buf_values[:n]
        if self.keep.columns is not None:
            rows = rows @ self.keep.columns
        if self.keep.block > 0:      # in-band rows go into the blocks, only others are kept
            self._accumulate_blocks(labels, rows)
            labels, stamps = labels[labels < 0], stamps[labels < 0]
        else:
            self._values.append(np.array(rows, dtype=np.float64))
        self._labels.append(labels)
        self._stamps.append(stamps)
        self._n = 0

    def _accumulate_blocks(self, labels: np.ndarray, rows: np.ndarray) -> None:
        valid = labels >= 0
        ids, inverse = np.unique(labels[valid] // self.keep.block, return_inverse=True)
        values = rows[valid]
        width = values.shape[1]
        sums = np.zeros((ids.size, 1 + 2 * width))
        np.add.at(sums[:, 0], inverse, 1.0)
        np.add.at(sums[:, 1:1 + width], inverse, values)
        np.add.at(sums[:, 1 + width:], inverse, values ** 2)
        for k, block in enumerate(ids.tolist()):
            if block in self._blocks:
                self._blocks[block] += sums[k]
            else:
                self._blocks[block] = sums[k]

    def _block_series(self, base: StrutSeries) -> StrutSeries:
        """``base`` with its rows replaced by the per-block means and RMS deviations."""
        blocks = sorted(self._blocks)
        if not blocks:
            return base
        sums = np.stack([self._blocks[b] for b in blocks])
        width = (sums.shape[1] - 1) // 2
        count = sums[:, :1]
        mean = sums[:, 1:1 + width] / count
        rms = np.sqrt(np.maximum(sums[:, 1 + width:] / count - mean ** 2, 0.0))
        return dataclasses.replace(
            base, sample_index=np.asarray(blocks, np.int64) * self.keep.block,
            values=np.hstack([mean, rms]), timestamp_ns=np.zeros(0, np.int64))

    def series(self, t0_ns: int, sample_rate_hz: float) -> StrutSeries:
        """Place the messages on their samples: sort, drop duplicates, count gaps."""
        self._flush()
        width = STRUT_COUNT if self.keep.columns is None else int(self.keep.columns.shape[1])
        labels = np.concatenate(self._labels) if self._labels else np.zeros(0, np.int64)
        stamps = np.concatenate(self._stamps) if self._stamps else np.zeros(0, np.int64)
        values = (np.concatenate(self._values) if self._values
                  else np.zeros((labels.size if self.keep.block > 0 else 0, width)))
        if self.keep.block > 0:
            values = np.zeros((labels.size, width))   # rows went into the blocks
        self._labels, self._stamps, self._values = [], [], []
        invalid = self.invalid
        if self._set.count:
            source: IndexSource = 'in-band'
            labelled = labels >= 0
            invalid += int(np.count_nonzero(~labelled))
            index, stamps, values = labels[labelled], stamps[labelled], values[labelled]
            order = np.argsort(index, kind='stable')
            index, stamps, values = index[order], stamps[order], values[order]
            distinct, duplicates = self._set.count, self.duplicates
            first, last = self._set.first, self._set.last
        else:
            source = 'timestamp'
            index = _index_from_timestamps(stamps, t0_ns, sample_rate_hz)
            order = np.argsort(index, kind='stable')  # stable: the first copy comes first
            index, stamps, values = index[order], stamps[order], values[order]
            keep = np.ones(index.shape, dtype=bool)
            keep[1:] = index[1:] != index[:-1]
            duplicates = int(np.count_nonzero(~keep))
            index, stamps, values = index[keep], stamps[keep], values[keep]
            distinct = int(index.size)
            first = int(index[0]) if index.size else -1
            last = int(index[-1]) if index.size else -1
        series = StrutSeries(
            topic=self.topic,
            sample_index=index,
            values=values,
            timestamp_ns=stamps if self.keep.timestamps else np.zeros(0, np.int64),
            missing_samples=(last - first + 1 - distinct) if distinct else 0,
            duplicate_samples=duplicates,
            index_source=source,
            invalid_messages=invalid,
            samples=distinct,
            first_sample=first,
            last_sample=last,
        )
        if self.keep.block > 0:
            series = (self._block_series(series) if source == 'in-band' else dataclasses.replace(
                series, sample_index=np.zeros(0, np.int64), values=np.zeros((0, 2 * width))))
        return series


def _index_from_timestamps(timestamps: np.ndarray, t0_ns: int, sample_rate_hz: float) -> np.ndarray:
    """``round((t - t0) * fs)`` on the bag timestamps (ns), as int64."""
    return np.rint((timestamps - t0_ns) * (sample_rate_hz * 1e-9)).astype(np.int64)


# --------------------------------------------------------------------------- CDR decoding

_DECODE_ERRORS = (struct.error, ValueError, IndexError, UnicodeDecodeError, SerdeError,
                  AssertionError, KeyError, TypeError, OverflowError, MemoryError)


def decode_strut_message(data: bytes | memoryview) -> tuple[np.ndarray, int | None]:
    """Six values and the in-band sample index of a serialized Float64MultiArray.

    Little-endian CDR (what ROS 2 middlewares on x86 and ARM write) is decoded directly,
    a few microseconds a message; other encapsulations go through rosbags' deserializer.

    Raises:
        InvalidStrutMessage: Undecodable bytes, not six finite values, a garbled or
            out-of-range sample label.
    """
    try:
        values, labels = _decode_array(data)
    except _DECODE_ERRORS as err:
        raise InvalidStrutMessage(f'undecodable message ({err.__class__.__name__})') from None
    if values.shape != (STRUT_COUNT,):
        raise InvalidStrutMessage(f'expected {STRUT_COUNT} strut values, got {values.size}')
    if not np.isfinite(values).all():
        raise InvalidStrutMessage('non-finite strut value')
    if len(labels) < 2:
        return values, None
    index = parse_sample_label(labels[1])
    if index >= MAX_BAG_SAMPLE_INDEX:
        raise InvalidStrutMessage(f'sample index {index} out of range')
    return values, index


# --------------------------------------------------------------------------- one pass


@dataclass
class BagContent:
    """What one pass over a bag collected (see :func:`read_bag`)."""

    path: Path
    strut: dict[str, StrutSeries]
    diagnostics: list[tuple[int, str, dict]]
    weights_index: np.ndarray
    weights: np.ndarray
    parameter_events: list[tuple[int, Any]]
    clock: tuple[np.ndarray, np.ndarray]
    custom_data: dict[str, str]
    recovered: str = ''
    """Empty for a closed bag; else how an unfinished recording was read."""
    bad_messages: dict[str, int] = field(default_factory=dict)
    """Undecodable messages skipped on the other topics, per topic."""
    frequencies: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    """Per topic of :data:`FREQUENCY_TOPICS` recorded: (sample index (N,), Hz (N, K)),
    sorted by sample, K the most values any message had (fewer: NaN-padded)."""
    sensitivity: list[tuple[int, dict[str, np.ndarray]]] = field(default_factory=list)
    """``/pph/notch_sensitivity`` messages: (sample index, {row name: values (F,)})."""


def read_bag(
    bag_path: str | Path,
    strut: Mapping[str, Keep] | None = None,
    sample_rate_hz: float = SAMPLE_RATE_HZ,
    required: Sequence[str] | None = None,
    weights_every: int = 1,
    parameter: tuple[str, str] = ('/notch_controller', 'enabled'),
) -> BagContent:
    """Read everything the analysis uses in ONE streaming pass over the bag.

    Strut topics are decoded into compact arrays as they stream by (``strut``: what to
    keep of each, default every value of :data:`STRUT_TOPICS`); ``/diagnostics``,
    ``/pph/notch_weights`` (every ``weights_every``-th message), ``/parameter_events``
    (values of ``parameter`` = (node, name)) and ``/clock`` are collected too. An
    undecodable message is skipped and counted, never fatal. A recording that was not
    closed (no ``metadata.yaml``, or the provisional one ``pph_recorder`` writes when it
    starts) is read up to its last complete record, and ``recovered`` says so.

    Raises:
        BagError: Missing, truncated or corrupt bag; a required topic is absent (the
            message lists the bag's topics); a strut topic of another type.
    """
    keeps = dict(strut) if strut is not None else dict.fromkeys(STRUT_TOPICS, KEEP_ALL)
    if required is None:
        required = (ACCEL_TOPIC,) if ACCEL_TOPIC in keeps else ()
    reader = _open_reader(bag_path)
    try:
        absent = [t for t in required if t not in reader.topics]
        if absent:
            raise BagError(
                f'bag {reader.path} has no {", ".join(absent)}; its topics: '
                f'{_topics_summary(reader)}'
            )
        struts = _check_strut_connections(reader, tuple(keeps))
        wanted = {DIAGNOSTICS_TOPIC: DIAGNOSTICS_MSGTYPE, WEIGHTS_TOPIC: STRUT_MSGTYPE,
                  PARAMETER_EVENTS_TOPIC: PARAMETER_EVENT_MSGTYPE, CLOCK_TOPIC: CLOCK_MSGTYPE,
                  SENSITIVITY_TOPIC: STRUT_MSGTYPE,
                  **dict.fromkeys(FREQUENCY_TOPICS, STRUT_MSGTYPE)}
        others = [c for c in reader.connections if wanted.get(c.topic) == c.msgtype]
        return _stream(reader, struts, others, keeps, sample_rate_hz, weights_every,
                       parameter)
    finally:
        reader.close()


def _stream(reader: Any, struts: list[Connection], others: list[Connection],
            keeps: Mapping[str, Keep], sample_rate_hz: float, weights_every: int,
            parameter: tuple[str, str]) -> BagContent:
    """The pass of :func:`read_bag` over an open reader."""
    streams = {c.topic: _TopicStream(c.topic, keeps[c.topic]) for c in struts}
    by_id = {c.id: streams[c.topic] for c in struts}
    diagnostics: list[tuple[int, str, dict]] = []
    events: list[tuple[int, Any]] = []
    clock: list[tuple[int, int]] = []
    weights = _WeightsStream(weights_every)
    vectors = {topic: _VectorStream() for topic in FREQUENCY_TOPICS}
    sensitivity: list[tuple[int, dict[str, np.ndarray]]] = []
    bad: dict[str, int] = {}
    store = typestore()
    for conn, timestamp, data in _iter_messages(reader, [*struts, *others]):
        stream = by_id.get(conn.id)
        if stream is not None:
            stream.add(timestamp, data)
            continue
        try:
            if conn.topic == WEIGHTS_TOPIC:
                weights.add(data)
                continue
            if conn.topic in vectors:
                vectors[conn.topic].add(data)
                continue
            msg = store.deserialize_cdr(bytes(data), conn.msgtype)
            if conn.topic == SENSITIVITY_TOPIC:
                sensitivity.append(table_of_message(msg))
                continue
            if conn.topic == DIAGNOSTICS_TOPIC:
                diagnostics.extend((timestamp, st.name, {kv.key: kv.value for kv in st.values})
                                   for st in msg.status)
            elif conn.topic == CLOCK_TOPIC:
                clock.append((timestamp, msg.clock.sec * 1_000_000_000 + msg.clock.nanosec))
            elif conn.topic == PARAMETER_EVENTS_TOPIC and msg.node == parameter[0]:
                events.extend((timestamp, _parameter_value(p.value))
                              for p in (*msg.new_parameters, *msg.changed_parameters)
                              if p.name == parameter[1])
        except _DECODE_ERRORS:
            bad[conn.topic] = bad.get(conn.topic, 0) + 1
    starts = [s.first_timestamp for s in streams.values() if s.first_timestamp is not None]
    t0_ns = min(starts) if starts else 0
    series = {topic: s.series(t0_ns, sample_rate_hz) for topic, s in streams.items()}
    stamps = np.array([t for t, _ in clock], dtype=np.int64)
    clock_ns = np.array([c for _, c in clock], dtype=np.int64)
    w_index, w_values = weights.arrays()
    return BagContent(Path(reader.path), series, diagnostics, w_index, w_values, events,
                      (stamps, clock_ns), _custom_data(reader), getattr(reader, 'recovered', ''),
                      bad, {t: v.arrays() for t, v in vectors.items() if v.rows}, sensitivity)


def _decode_array(data: bytes | memoryview) -> tuple[np.ndarray, list[str]]:
    """Values and dimension labels of a serialized Float64MultiArray.

    Little-endian CDR is decoded directly; other encapsulations go through rosbags.
    """
    raw = bytes(data)
    if raw[:2] in LITTLE_ENDIAN_CDR:
        return decode_float64_array(raw)
    msg = typestore().deserialize_cdr(raw, STRUT_MSGTYPE)
    return np.asarray(msg.data, dtype=np.float64), [d.label for d in msg.layout.dim]


class _VectorStream:
    """Messages of a frequency topic: values (Hz) per sample, first message per sample kept."""

    def __init__(self) -> None:
        self.rows: dict[int, np.ndarray] = {}

    def add(self, data: bytes | memoryview) -> None:
        values, labels = _decode_array(data)
        if len(labels) < 2 or not np.all(np.isfinite(values)):
            raise ValueError('no sample index, or a non-finite value')
        self.rows.setdefault(parse_sample_label(labels[1]), values)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        index = np.array(sorted(self.rows), dtype=np.int64)
        width = max(v.size for v in self.rows.values())
        table = np.full((index.size, width), np.nan)
        for row, n in enumerate(index):
            values = self.rows[int(n)]
            table[row, :values.size] = values
        return index, table


def table_of_message(msg: Any) -> tuple[int, dict[str, np.ndarray]]:
    """(sample index, {row name: values}) of a ``/pph/notch_sensitivity`` message.

    Raises:
        ValueError: Not the layout ``ros.messages.make_table_array`` writes.
    """
    dims = msg.layout.dim
    if len(dims) < 3 or not dims[0].label.startswith(SENSITIVITY_ROWS_PREFIX):
        raise ValueError('not a table message')
    names = dims[0].label[len(SENSITIVITY_ROWS_PREFIX):].split(',')
    table = np.asarray(msg.data, dtype=np.float64).reshape(len(names), int(dims[1].size))
    return parse_sample_label(dims[2].label), dict(zip(names, table, strict=True))


class _WeightsStream:
    """``/pph/notch_weights`` messages ``[tone][strut][a, b]`` (N), every n-th one kept.

    Messages whose tone count differs from the last message's (tones changed) are dropped.
    """

    def __init__(self, every: int) -> None:
        self.every = max(1, int(every))
        self.index: list[int] = []
        self.rows: list[np.ndarray] = []
        self.tones = -1
        self._seen = 0

    def add(self, data: bytes | memoryview) -> None:
        self._seen += 1
        if (self._seen - 1) % self.every:
            return
        msg = typestore().deserialize_cdr(bytes(data), STRUT_MSGTYPE)
        dims = msg.layout.dim
        if len(dims) < 4:
            return
        tones = int(dims[0].size)
        if msg.data.size != tones * 12:
            return
        try:
            sample = parse_sample_label(dims[3].label)
        except InvalidStrutMessage:
            return
        if tones != self.tones:
            self.index, self.rows, self.tones = [], [], tones
        self.index.append(sample)
        self.rows.append(np.asarray(msg.data, dtype=float).reshape(tones, 6, 2))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.rows:
            return np.zeros(0, dtype=np.int64), np.zeros((0, max(self.tones, 0), 6, 2))
        return np.asarray(self.index, dtype=np.int64), np.stack(self.rows)


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
    return read_bag(bag_path, dict.fromkeys(topics, KEEP_ALL), sample_rate_hz, required).strut


def read_clock(bag_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """``/clock`` of a bag: (bag timestamps (ns), clock times (ns)), int64 arrays.

    Both are empty when ``/clock`` was not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    return read_bag(bag_path, {}).clock


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
    return read_bag(bag_path, {}, parameter=(node, name)).parameter_events


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



def read_diagnostics(bag_path: str | Path, name_prefix: str = '') -> list[tuple[int, str, dict]]:
    """Statuses on ``/diagnostics``: ``[(bag timestamp (ns), status name, {key: value})]``.

    Only statuses whose name starts with ``name_prefix``; empty if not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    return [d for d in read_bag(bag_path, {}).diagnostics if d[1].startswith(name_prefix)]


def read_notch_weights(bag_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Notch weights from ``/pph/notch_weights``: (sample index (N,), a/b (N, T, 6, 2)).

    Messages whose tone count differs from the last message's (tones changed) are skipped.
    Both arrays are empty if the topic was not recorded.

    Raises:
        BagError: Missing, truncated or corrupt bag.
    """
    content = read_bag(bag_path, {})
    return content.weights_index, content.weights
