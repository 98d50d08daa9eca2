"""Everything the analysis reads from a bag, in one streaming pass.

Uses ``rosbags`` only (no rclpy import), so the analysis runs on any machine with numpy.
Reads MCAP and sqlite3 bags, written by ``ros2 bag record``, by the package's
``pph_recorder`` or by :func:`~hexapod_vibration.analysis.bag_writer.write_strut_bag`; each
value is placed on its loop sample (:mod:`hexapod_vibration.analysis.strut_streams`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Connection

from hexapod_vibration.analysis.bag_files import (
    BagError,
    custom_data_of,
    iter_messages,
    open_reader,
    strut_connections,
    topics_summary,
)
from hexapod_vibration.analysis.bag_format import (
    ACCEL_TOPIC,
    CLOCK_MSGTYPE,
    CLOCK_TOPIC,
    DIAGNOSTICS_MSGTYPE,
    DIAGNOSTICS_TOPIC,
    FREQUENCY_TOPICS,
    PARAMETER_EVENT_MSGTYPE,
    PARAMETER_EVENTS_TOPIC,
    SENSITIVITY_TOPIC,
    STRUT_MSGTYPE,
    STRUT_TOPICS,
    WEIGHTS_TOPIC,
    typestore,
)
from hexapod_vibration.analysis.bag_messages import DECODE_ERRORS, parameter_value, table_of_message
from hexapod_vibration.analysis.strut_streams import (
    KEEP_ALL,
    Keep,
    StrutSeries,
    TopicStream,
    VectorStream,
    WeightsStream,
)
from hexapod_vibration.contract import SAMPLE_RATE_HZ


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
    recovered: str = ""
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
    parameter: tuple[str, str] = ("/notch_controller", "enabled"),
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
    reader = open_reader(bag_path)
    try:
        absent = [t for t in required if t not in reader.topics]
        if absent:
            raise BagError(
                f'bag {reader.path} has no {", ".join(absent)}; its topics: '
                f'{topics_summary(reader)}'
            )
        struts = strut_connections(reader, tuple(keeps))
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
    streams = {c.topic: TopicStream(c.topic, keeps[c.topic]) for c in struts}
    by_id = {c.id: streams[c.topic] for c in struts}
    diagnostics: list[tuple[int, str, dict]] = []
    events: list[tuple[int, Any]] = []
    clock: list[tuple[int, int]] = []
    weights = WeightsStream(weights_every)
    vectors = {topic: VectorStream() for topic in FREQUENCY_TOPICS}
    sensitivity: list[tuple[int, dict[str, np.ndarray]]] = []
    bad: dict[str, int] = {}
    store = typestore()
    for conn, timestamp, data in iter_messages(reader, [*struts, *others]):
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
                events.extend((timestamp, parameter_value(p.value))
                              for p in (*msg.new_parameters, *msg.changed_parameters)
                              if p.name == parameter[1])
        except DECODE_ERRORS:
            bad[conn.topic] = bad.get(conn.topic, 0) + 1
    starts = [s.first_timestamp for s in streams.values() if s.first_timestamp is not None]
    t0_ns = min(starts) if starts else 0
    series = {topic: s.series(t0_ns, sample_rate_hz) for topic, s in streams.items()}
    stamps = np.array([t for t, _ in clock], dtype=np.int64)
    clock_ns = np.array([c for _, c in clock], dtype=np.int64)
    w_index, w_values = weights.arrays()
    return BagContent(Path(reader.path), series, diagnostics, w_index, w_values, events,
                      (stamps, clock_ns), custom_data_of(reader), getattr(reader, "recovered", ""),
                      bad, {t: v.arrays() for t, v in vectors.items() if v.rows}, sensitivity)


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


def read_parameter_events(
    bag_path: str | Path, node: str = "/notch_controller", name: str = "enabled"
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
