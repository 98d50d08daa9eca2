"""Conversion between ``std_msgs/Float64MultiArray`` and per-strut values with a sample index.

Every ``/pph/*`` topic carries six values in strut order 1..6 (SI units: m/s^2, m or N) with
``layout.dim[0] = ("strut", 6, 6)``. The driver and the controllers add
``layout.dim[1] = ("sample:<n>", 1, 1)`` and ``layout.dim[2] = ("run:<id>", 1, 1)``: the
array keeps its 6 values (shape (6, 1, 1)) and carries the loop's sample index ``n`` and the
driver's run in band, so commands pair with samples exactly, a restarted driver is told
apart (:mod:`hexapod_vibration.core.loop.sample_sequence`), and the analysis places every
value on its sample whatever the transport jitter.

Two forms of the same message, both at 1 kHz, without per-element Python work:

- Python messages (:func:`make_strut_array`, :func:`parse_strut_array`: about 6 us to make,
  2.5 us to parse), for tools and tests;
- serialized CDR bytes, what the nodes' loop publishes (:class:`StrutArrayPublisher`) and
  receives (loop subscriptions are raw, :func:`create_loop_subscription`): the codec is
  :mod:`hexapod_vibration.cdr`.

Receiving never raises: :func:`receive_strut_sample` returns None for a message it refuses,
and :class:`ControllerLoopPort` adds the physical range and the run/sequence rules a
controller needs, with one counter per reason for ``/diagnostics``.
"""

from __future__ import annotations

import array
import math
import struct
from collections import Counter
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from hexapod_vibration.cdr import (
    Dimension,
    UnsupportedCdr,
    decode_float64_array,
    decode_strut_cdr,
    encode_strut_cdr,
    vector_layout,
    weights_data,
    weights_layout,
)
from hexapod_vibration.contract import (
    FREQUENCY_LABEL,
    SENSITIVITY_ROWS_PREFIX,
    STRUT_COUNT,
    STRUT_LABEL,
    InvalidStrutMessage,
    StrutSample,
    parse_layout_labels,
    run_label,
    sample_label,
)
from hexapod_vibration.core.loop.sample_sequence import Admission, SampleSequence
from hexapod_vibration.core.loop.signal_ranges import out_of_range
from hexapod_vibration.ros.qos import LOOP_QOS
from hexapod_vibration.ros.rclpy_internals import serialized_publish

__all__ = [
    "ControllerLoopPort",
    "InvalidStrutMessage",
    "LoopSample",
    "StrutArrayPublisher",
    "StrutSample",
    "UnsupportedCdr",
    "create_loop_subscription",
    "create_parsed_subscription",
    "make_strut_array",
    "make_table_array",
    "make_vector_array",
    "make_weights_array",
    "parse_labelled_sample",
    "parse_vector_sample",
    "parse_strut_array",
    "parse_strut_sample",
    "receive_strut_array",
    "receive_strut_sample",
]

_FLOAT64 = np.dtype(np.float64)
_DECODE_ERRORS = (InvalidStrutMessage, ValueError, TypeError, struct.error)
"""What decoding a hostile message may raise; each is a refusal, never an escape."""


def make_strut_array(
    values: np.ndarray | Sequence[float], sample_index: int | None, run: int | None = None
) -> Float64MultiArray:
    """Build a ``/pph/*`` message from six per-strut values.

    Args:
        values: Six values in strut order 1..6, SI units of the topic (m/s^2, m or N).
        sample_index: Loop sample index ``n`` (>= 0) the values belong to, carried in
            ``layout.dim[1]``; ``None`` leaves it out (shape (6,), as other publishers do).
        run: The driver's run identity, carried in ``layout.dim[2]`` (needs an index);
            ``None`` leaves it out.

    Returns:
        The message, ready to publish.

    Raises:
        ValueError: ``values`` does not hold exactly six numbers, ``sample_index`` < 0,
            or ``run`` out of range or given without an index.
    """
    flat = np.ascontiguousarray(values, dtype=_FLOAT64).reshape(-1)
    if flat.shape[0] != STRUT_COUNT:
        raise ValueError(f"expected {STRUT_COUNT} strut values, got {flat.shape[0]}")
    dims = [MultiArrayDimension(label=STRUT_LABEL, size=STRUT_COUNT, stride=STRUT_COUNT)]
    if sample_index is not None:
        dims.append(MultiArrayDimension(label=sample_label(sample_index), size=1, stride=1))
    if run is not None:
        if sample_index is None:
            raise ValueError("a run needs a sample index")
        dims.append(MultiArrayDimension(label=run_label(run), size=1, stride=1))
    msg = Float64MultiArray()
    msg.layout.dim = dims
    msg.data = array.array("d", flat.tobytes())
    return msg


def parse_strut_sample(msg: Float64MultiArray) -> StrutSample:
    """Extract the six values, the sample index and the run of a ``/pph/*`` message.

    ``layout.dim[0]`` is not checked: a publisher that sends six values without a layout
    (e.g. ``ros2 topic pub``) is accepted, without a sample index.

    Returns:
        ``values`` is a read-only float64 view of shape (6,) on the message's buffer (copy
        it if the message is mutated afterwards); ``index`` and ``run`` are None when the
        publisher did not send them.

    Raises:
        InvalidStrutMessage: Not six values, a value is NaN or infinite, or
            ``layout.dim[1]`` / ``layout.dim[2]`` hold a garbled sample or run label.
    """
    data = msg.data
    if len(data) != STRUT_COUNT:
        raise InvalidStrutMessage(f"expected {STRUT_COUNT} strut values, got {len(data)}")
    if not all(map(math.isfinite, data)):
        raise InvalidStrutMessage(f"non-finite strut value in {list(data)}")
    if isinstance(data, array.array):
        values = np.frombuffer(data, dtype=_FLOAT64)
    else:
        values = np.asarray(data, dtype=_FLOAT64)
    values.flags.writeable = False
    index, run = parse_layout_labels([d.label for d in msg.layout.dim[:3]])
    return StrutSample(values, index, run)


def parse_strut_array(msg: Float64MultiArray) -> tuple[np.ndarray, int | None]:
    """``(values, sample_index)`` of :func:`parse_strut_sample` (same rules)."""
    values, index, _ = parse_strut_sample(msg)
    return values, index


class StrutArrayPublisher:
    """Publish ``/pph/*`` messages at 1 kHz as serialized bytes (``encode_strut_cdr``).

    The bytes are what rclpy would serialize from :func:`make_strut_array` (subscribers
    see the same message), without building the Python message and converting it.
    Measured on the project's 2-core machine (no subscriber): 3.7 us per publish against
    8.1 us for a reused Python message and 15.0 us for :func:`make_strut_array` + publish.
    """

    def __init__(self, publisher: Any) -> None:
        """Wrap an rclpy publisher of ``std_msgs/Float64MultiArray``."""
        self.publish_bytes: Callable[[bytes], None] = serialized_publish(publisher)
        """Publish bytes made by :meth:`encode` (e.g. again)."""

    @staticmethod
    def encode(values: np.ndarray | Sequence[float], sample_index: int,
               run: int | None = None) -> bytes:
        """The bytes :meth:`publish` sends."""
        return encode_strut_cdr(values, sample_index, run)

    def publish(self, values: np.ndarray | Sequence[float], sample_index: int,
                run: int | None = None) -> bytes:
        """Publish six values (SI units of the topic) for loop sample ``sample_index`` >= 0.

        Returns:
            The bytes published.

        Raises:
            ValueError: ``values`` does not hold exactly six numbers or the index is < 0.
        """
        raw = encode_strut_cdr(values, sample_index, run)
        self.publish_bytes(raw)
        return raw


def create_loop_subscription(node: Node, topic: str, callback: Callable[[bytes], None],
                             qos: QoSProfile = LOOP_QOS) -> Subscription:
    """A raw (bytes) 1 kHz loop subscription of ``node`` (QoS :data:`LOOP_QOS` by default).

    Raw on every executor, so no received loop message goes through rclpy's deserializer
    (which raises on malformed bytes and misreads impossible layouts, see
    :mod:`hexapod_vibration.cdr`): the callback decodes the bytes.
    """
    return node.create_subscription(Float64MultiArray, topic, callback, qos, raw=True)


PARSED_MAX_VALUES = 4096
"""Most values a :func:`create_parsed_subscription` message may carry (a forecast: 1 200)."""


class DecodedArray:
    """A ``Float64MultiArray``'s values and dimension labels, decoded from its CDR bytes.

    What the parsers read of a message (``data``, ``layout.dim[i].label``) without building
    the Python message: rclpy's deserializer calls the message's Python constructor, and a
    stop signal (Ctrl-C) handled there came out as a ``TypeError`` traceback from a
    realtime driver taking 200 forecasts a second.
    """

    def __init__(self, raw: bytes) -> None:
        """Decode (``cdr.decode_float64_array``; it raises on bytes it cannot read)."""
        self.data, labels = decode_float64_array(raw, PARSED_MAX_VALUES)
        self.layout = SimpleNamespace(dim=[SimpleNamespace(label=label) for label in labels])


def create_parsed_subscription(node: Node, topic: str,
                               parse: Callable[[Float64MultiArray], tuple],
                               on_parsed: Callable[..., None], qos: QoSProfile
                               ) -> Subscription:
    """A raw loop subscription that decodes, checks with ``parse`` and hands it on.

    ``on_parsed(*parse(msg))`` for each good message; a message that cannot be decoded
    (:class:`DecodedArray`) or ``parse`` refuses (:class:`InvalidStrutMessage`) is logged
    (throttled) and changes nothing.
    """
    def callback(msg: Float64MultiArray | bytes) -> None:
        try:
            if isinstance(msg, bytes | bytearray | memoryview):
                msg = DecodedArray(bytes(msg))
            parsed = parse(msg)
        except (*_DECODE_ERRORS, UnsupportedCdr, UnicodeDecodeError) as exc:
            node.get_logger().warn(f"{topic}: rejected message ({exc})",
                                   throttle_duration_sec=1.0)
            return
        on_parsed(*parsed)

    return create_loop_subscription(node, topic, callback, qos)


def receive_strut_sample(msg: Float64MultiArray | bytes, logger: Any, topic: str
                         ) -> StrutSample | None:
    """:func:`parse_strut_sample` for a subscription callback: None for a refused message.

    ``msg`` is the message or its serialized bytes. Nothing raises: malformed bytes, an
    impossible layout, a bad label or value are a refusal. Its reason is logged as a
    warning, throttled by rclpy to once a second per process (keyed by this call site);
    the caller counts every refusal.
    """
    try:
        if isinstance(msg, bytes | bytearray | memoryview):
            return decode_strut_cdr(bytes(msg))
        return parse_strut_sample(msg)
    except _DECODE_ERRORS as exc:
        logger.warn(f"{topic}: rejected message ({exc})", throttle_duration_sec=1.0)
        return None


def receive_strut_array(msg: Float64MultiArray | bytes, logger: Any, topic: str
                        ) -> tuple[np.ndarray, int | None] | None:
    """``(values, sample_index)`` of :func:`receive_strut_sample`, or None."""
    sample = receive_strut_sample(msg, logger, topic)
    return None if sample is None else (sample.values, sample.index)


class LoopSample(NamedTuple):
    """A received sample a controller acts on (a named tuple: one a sample, made cheaply)."""

    values: np.ndarray
    """Six values (SI units of the topic), read-only."""
    index: int
    """Its sample index (a publisher without one: the one after the last)."""
    run: int | None
    """The driver's run (None from a publisher without one)."""
    gap: int
    """Samples of this run missing since the last one acted on."""
    new_run: bool
    """First sample of a run adopted after another one (a restarted driver): reset the
    run-dependent state (integrators, identification, phase references) before acting."""
    skipped: tuple[StrutSample, ...] = ()
    """Older samples of this run, queued with it and skipped for it (oldest first): they
    fall in its gap (:meth:`ControllerLoopPort.hold_skipped`)."""


class ControllerLoopPort:
    """A controller's end of the loop: one topic's samples in, one command per sample out.

    :meth:`receive` decodes (never raises), refuses values beyond ``limit_abs`` (the
    sensor's physical range) and applies the run and sequence rules of
    :class:`~hexapod_vibration.core.loop.sample_sequence.SampleSequence`; it returns the
    samples to act on. :meth:`answer` publishes the command of a sample with its index and
    run. A sample offered again (lockstep re-offers a sample whose commands it misses) is
    answered again with the same bytes, without acting. ``counters`` has one count per
    reason for ``/diagnostics``.
    """

    def __init__(self, topic: str, limit_abs: float, publisher: StrutArrayPublisher,
                 logger: Any, sequence: SampleSequence | None = None,
                 counts_gaps: bool = True) -> None:
        """Receive on ``topic``, answer through ``publisher``, log through ``logger``.

        ``counts_gaps`` False: the controller's core counts the samples missing between
        those acted on (``missed_samples``), not the port.
        """
        self.topic = topic
        self.counts_gaps = counts_gaps
        self.limit_abs = limit_abs
        self.publisher = publisher
        self.logger = logger
        self.sequence = sequence or SampleSequence()
        self.counters: Counter = Counter()
        self._answer: tuple[int | None, int, bytes] | None = None
        self._skipped: list[StrutSample] = []

    @property
    def last_sample(self) -> int:
        """Index of the last sample acted on (-1 before any)."""
        return self.sequence.last

    def last_acted(self) -> tuple[int, int | None]:
        """``(index, run)`` of the last sample acted on (``(-1, None)`` before any)."""
        return self.sequence.last, self.sequence.run

    @property
    def invalid(self) -> int:
        """Messages refused as malformed or out of range."""
        return self.counters["malformed"] + self.counters["out_of_range"]

    def receive(self, msg: Float64MultiArray | bytes) -> LoopSample | None:
        """The sample to act on, or None (refused, repeated, late or unconfirmed)."""
        skipped = self._skipped
        if skipped:                              # rare (a loop behind): no allocation else
            self._skipped = []
        sample = receive_strut_sample(msg, self.logger, self.topic)
        if sample is None:
            self.counters["malformed"] += 1
            return None
        reason = out_of_range(sample.values, self.limit_abs)
        if reason:
            self.counters["out_of_range"] += 1
            self.logger.warn(f"{self.topic}: rejected message ({reason})",
                             throttle_duration_sec=1.0)
            return None
        verdict = self.sequence.admit(sample.index, sample.run)
        if not verdict.act:
            self._not_acted(verdict.admission, verdict.index, sample.run)
            return None
        new_run = verdict.admission is Admission.NEW_RUN and self.sequence.runs_adopted > 1
        if new_run:
            self.counters["new_runs"] += 1
            self.logger.info(f"{self.topic}: new run {sample.run} from sample {verdict.index}")
        if self.counts_gaps:
            self.counters["missed_samples"] += verdict.gap
        if skipped and not new_run:
            skipped = tuple(s for s in skipped if s.index < verdict.index)
            return LoopSample(sample.values, verdict.index, sample.run, verdict.gap, new_run,
                              skipped)
        return LoopSample(sample.values, verdict.index, sample.run, verdict.gap, new_run)

    def hold_skipped(self, msg: Float64MultiArray | bytes) -> None:
        """An older queued message skipped for a newer one (a loop behind).

        Kept if decoded, in range, of the run in force and after the last sample acted on;
        the next sample acted on carries those before it (``LoopSample.skipped``). The
        sequence does not move: that sample finds the gap. Refusals are counted as by
        :meth:`receive`.
        """
        sample = receive_strut_sample(msg, self.logger, self.topic)
        if sample is None:
            self.counters["malformed"] += 1
        elif out_of_range(sample.values, self.limit_abs):
            self.counters["out_of_range"] += 1
        elif (sample.index is not None and sample.run == self.sequence.run
              and self.sequence.last < sample.index):
            self._skipped.append(sample)

    def _not_acted(self, admission: Admission, index: int, run: int | None) -> None:
        if admission is Admission.REPEAT:
            self.counters["repeats"] += 1
            if self._answer is not None and self._answer[:2] == (run, index):
                self.publisher.publish_bytes(self._answer[2])
        elif admission is Admission.LATE:
            self.counters["late"] += 1
        else:
            self.counters["unconfirmed"] += 1
            self.logger.warn(f"{self.topic}: sample {index} of run {run} does not follow "
                             f"sample {self.sequence.last} of run {self.sequence.run}: "
                             "ignored until confirmed", throttle_duration_sec=1.0)

    def answer(self, values: np.ndarray | Sequence[float], sample: LoopSample) -> None:
        """Publish ``values`` as the command for ``sample`` (its index and run)."""
        raw = self.publisher.publish(values, sample.index, sample.run)
        self._answer = (sample.run, sample.index, raw)

    def diagnostics(self) -> dict[str, int]:
        """Counters for ``/diagnostics``: ``invalid`` and one per reason."""
        keys = ("malformed", "out_of_range", "unconfirmed", "late", "repeats", "new_runs",
                *(("missed_samples",) if self.counts_gaps else ()))
        return {"invalid": self.invalid, **{k: self.counters[k] for k in keys}}


# --------------------------------------------------------------------------- other arrays
def make_vector_array(values: np.ndarray | Sequence[float], sample_index: int | None,
                      run: int | None = None, label: str = FREQUENCY_LABEL
                      ) -> Float64MultiArray:
    """A message of any number of values (e.g. frequencies, Hz) for loop sample ``n``.

    ``layout.dim[0] = (label, N, N)``, then ``("sample:<n>", 1, 1)`` and ``("run:<id>", 1,
    1)`` as on the strut topics (each left out when None; a run needs an index).
    """
    flat = np.ascontiguousarray(values, dtype=_FLOAT64).reshape(-1)
    return _float64_array(flat, vector_layout(flat.size, sample_index, run, label))


def _float64_array(flat: np.ndarray, dims: Sequence[Dimension]) -> Float64MultiArray:
    """The message of float64 ``flat`` with ``dims`` (the layouts of :mod:`..cdr`)."""
    msg = Float64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride)
                      for label, size, stride in dims]
    msg.data = array.array("d", flat.tobytes())
    return msg


def make_weights_array(weights: np.ndarray, sample_index: int) -> Float64MultiArray:
    """``/pph/notch_weights`` of sample n: the canceller's (T, C) complex weights W = a - j b.

    Layout ``("tone", T), ("strut", C), ("a_b", 2), ("sample:<n>", 1)``; data (a, b) per tone
    and strut (N).
    """
    return _float64_array(weights_data(weights), weights_layout(*weights.shape, sample_index))


def parse_vector_sample(msg: Float64MultiArray, length: int | None = None) -> StrutSample:
    """Values, sample index and run of a :func:`make_vector_array` message.

    A message without a layout (``ros2 topic pub``) is accepted without an index.

    Raises:
        InvalidStrutMessage: Not ``length`` values (when given), a non-finite value, or a
            garbled sample or run label.
    """
    values = np.asarray(msg.data, dtype=_FLOAT64)
    if length is not None and values.size != length:
        raise InvalidStrutMessage(f"expected {length} value(s), got {values.size}")
    if not np.all(np.isfinite(values)):
        raise InvalidStrutMessage(f"non-finite value in {values.tolist()}")
    index, run = parse_layout_labels([d.label for d in msg.layout.dim[:3]])
    return StrutSample(values, index, run)


def parse_labelled_sample(msg: Float64MultiArray, label: str, width: int) -> StrutSample:
    """:func:`parse_vector_sample` of a message of rows of ``width`` values (N x width).

    ``layout.dim[0]`` must be labelled ``label`` and a sample label present; no row is a
    whole number of rows.

    Raises:
        InvalidStrutMessage: another label, no sample label, a partial row, a non-finite
            value or a garbled label.
    """
    sample = parse_vector_sample(msg)
    found = msg.layout.dim[0].label if msg.layout.dim else ""
    if found != label or sample.index is None:
        raise InvalidStrutMessage(f"expected dim[0] {label!r} and a sample label, "
                                  f"got {found!r}")
    if sample.values.size % width:
        raise InvalidStrutMessage(f"expected rows of {width} values, got "
                                  f"{sample.values.size} values")
    return sample


def make_table_array(rows: dict[str, np.ndarray], sample_index: int) -> Float64MultiArray:
    """Named rows of equal length F (e.g. ``frequency_hz`` and |S| in dB) in one message.

    ``layout.dim[0] = ("rows:<name>,<name>,...", R, R F)``, ``dim[1] = ("frequency", F, 1)``,
    ``dim[2] = ("sample:<n>", 1, 1)``; data row-major.
    """
    names = list(rows)
    table = np.vstack([np.asarray(rows[name], dtype=_FLOAT64).reshape(-1) for name in names])
    r, f = table.shape
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label=SENSITIVITY_ROWS_PREFIX + ",".join(names), size=r,
                            stride=r * f),
        MultiArrayDimension(label="frequency", size=f, stride=1),
        MultiArrayDimension(label=sample_label(sample_index), size=1, stride=1)]
    msg.data = array.array("d", np.ascontiguousarray(table).tobytes())
    return msg
