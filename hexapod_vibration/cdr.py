"""The CDR bytes of the loop's messages, written and read by hand, without ROS.

One codec for the nodes and the bag analysis alike (no rclpy, no message classes):

- :func:`encode_strut_cdr`: the bytes of a ``/pph/*`` ``std_msgs/Float64MultiArray``
  (six values, ``sample:<n>`` and ``run:<id>`` in ``layout.dim``), exactly what rclpy
  serializes from ``ros.messages.make_strut_array`` (tested against it);
- :func:`decode_strut_cdr`: the gate every received loop message goes through. rclpy's
  own ``deserialize_message`` cannot be that gate: it raises ``RMWError`` on malformed
  bytes and turns an impossible layout (a huge ``dims`` count) into six garbage numbers;
- :func:`clock_cdr`: ``rosgraph_msgs/Clock`` at a sample's sim time (the driver's /clock);
- :func:`decode_float64_array` and :func:`sample_index_of_cdr`: any little-endian
  Float64MultiArray as a bag holds it (every label, any number of values), for the
  analysis and the recorder.

Plain CDR (XCDR1): a 4-byte encapsulation header, then the fields, each aligned to its size
counted from the end of the header.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Container, Sequence

import numpy as np

from hexapod_vibration.contract import (
    FREQUENCY_LABEL,
    MAX_RUN_ID,
    MAX_SAMPLE_INDEX,
    RUN_LABEL_PREFIX,
    SAMPLE_LABEL_PREFIX,
    SAMPLE_RATE_HZ,
    STRUT_COUNT,
    STRUT_LABEL,
    InvalidStrutMessage,
    StrutSample,
    parse_layout_labels,
    parse_sample_label,
    run_label,
    sample_label,
    sample_sim_time,
)

CDR_LE = b"\x00\x01"
"""Encapsulation of plain CDR (XCDR1), little endian."""
CDR_BE = b"\x00\x00"
"""Encapsulation of plain CDR (XCDR1), big endian."""
LITTLE_ENDIAN_CDR = (CDR_LE, b"\x00\x03")
"""Encapsulations :func:`decode_float64_array` reads (plain and parameter-list CDR, little
endian: the same bytes for a Float64MultiArray)."""
CDR_HEADER = 4
"""Encapsulation bytes; alignment counts from after them."""
MAX_LAYOUT_DIMS = 16
"""More ``layout.dim`` entries than this is an impossible layout for a loop message."""
MAX_ARRAY_VALUES = 64
"""More values than this is not a message of the loop's topics (:func:`decode_float64_array`)."""
MAX_BAG_SAMPLE_INDEX = 2**40
"""In-band sample indices at or above this (35 years at 1 kHz) are refused in a bag."""

_U32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}
_LE32 = _U32["<"]
_BYTE_ORDER = {CDR_LE: "<", CDR_BE: ">"}
_LOOP_LABELS = (1, 2)
"""``layout.dim`` entries whose labels a loop message carries: sample, then run."""
_EVERY_LABEL = range(MAX_LAYOUT_DIMS)
_SAMPLE_PREFIX = SAMPLE_LABEL_PREFIX.encode()
_STRUT_DIM0 = _LE32.pack(len(STRUT_LABEL) + 1) + STRUT_LABEL.encode() + b"\x00"
"""A loop message's first dimension label, at :data:`_DIM0_AT`."""
_DIM0_AT = CDR_HEADER + 4
"""Offset of the first dimension's label (after the encapsulation and the dims count)."""
_UNDER_2 = (bytes(4), _LE32.pack(1))
"""The dimension counts (little-endian uint32) of a layout with no second dimension."""
_SAMPLE_DIGITS = len(str(MAX_SAMPLE_INDEX))
_INDEX_LIMIT = min(MAX_SAMPLE_INDEX + 1, MAX_BAG_SAMPLE_INDEX)
"""Sample indices from here on are refused (a label's range, then a bag's)."""


# ---------------------------------------------------------------------------- writing
_NUL_PADDING = tuple(bytes(1 + (-(k + 1) % 4)) for k in range(4))
"""A string's NUL and padding to 4 bytes, by its length modulo 4."""
_ALIGN8 = tuple(bytes(k) for k in range(8))
_ONE_ONE = struct.pack("<II", 1, 1)            # size and stride of dim[1] and dim[2]


def cdr_string(text: bytes) -> bytes:
    """CDR string at a 4-aligned position: length (NUL included), bytes, NUL, padding."""
    return _LE32.pack(len(text) + 1) + text + _NUL_PADDING[len(text) & 3]


_PREFIX = {dims: CDR_LE + b"\x00\x00" + _LE32.pack(dims) + cdr_string(STRUT_LABEL.encode())
           + _LE32.pack(STRUT_COUNT) + _LE32.pack(STRUT_COUNT) for dims in (2, 3)}
"""Encapsulation, dims count, dim[0] = ("strut", 6, 6): the same for every loop message."""
_DATA_HEADER = struct.pack("<II", 0, STRUT_COUNT)   # data_offset, length of data
_SAMPLE_FORMAT = _SAMPLE_PREFIX + b"%d"
_RUN_FORMAT = RUN_LABEL_PREFIX.encode() + b"%d"
_SAMPLE_LENGTH_AT = len(_PREFIX[3])
"""Offset of a loop message's second label (``sample:<n>``): its length, then its text."""
_SAMPLE_AT = _SAMPLE_LENGTH_AT + 4 + len(_SAMPLE_PREFIX)
"""Offset of the sample label's first digit in a loop message."""
_DIMS, _DIM0, _SAMPLE_PREFIX_BYTES = (slice(CDR_HEADER, _DIM0_AT),
                                      slice(_DIM0_AT, _DIM0_AT + len(_STRUT_DIM0)),
                                      slice(_SAMPLE_AT - len(_SAMPLE_PREFIX), _SAMPLE_AT))
"""Where a loop message has its dims count, first label and second label's prefix."""
_RUN_AT = _SAMPLE_AT + 1 + len(_ONE_ONE) + 4 + len(RUN_LABEL_PREFIX)
"""Offset of the run label's first digit in a loop message whose sample label has no digit:
add its digits' count rounded up to 4 (the label's NUL and padding)."""
_RUN_DIGITS = len(str(MAX_RUN_ID))
"""Most digits a run label may carry."""


def encode_strut_cdr(values: np.ndarray | Sequence[float], sample_index: int,
                     run: int | None = None) -> bytes:
    """The serialized (little-endian CDR) form of ``make_strut_array(values, index, run)``.

    A few microseconds, against about 15 us for building the message and serializing it
    with rclpy.

    Raises:
        ValueError: ``values`` does not hold exactly six numbers, ``sample_index`` < 0 or
            ``run`` < 1.
    """
    flat = np.asarray(values, dtype="<f8")
    if flat.size != STRUT_COUNT:
        raise ValueError(f"expected {STRUT_COUNT} strut values, got {flat.size}")
    if sample_index < 0:
        raise ValueError(f"sample index must be >= 0, got {sample_index}")
    if run is not None and run < 1:
        raise ValueError(f"run id must be >= 1, got {run}")
    head = _loop_head(sample_index, run)
    return b"".join((head, _ALIGN8[(CDR_HEADER - len(head)) & 7], flat.tobytes()))


def _loop_head(sample_index: int, run: int | None) -> bytes:
    """A loop message's bytes up to its data's alignment: layout, data_offset, length 6."""
    if run is None:
        return b"".join((_PREFIX[2], cdr_string(_SAMPLE_FORMAT % sample_index), _ONE_ONE,
                         _DATA_HEADER))
    return b"".join((_PREFIX[3], cdr_string(_SAMPLE_FORMAT % sample_index), _ONE_ONE,
                     cdr_string(_RUN_FORMAT % run), _ONE_ONE, _DATA_HEADER))


Dimension = tuple[str, int, int]
"""A ``MultiArrayDimension``: label, size, stride."""


def vector_layout(size: int, sample_index: int | None, run: int | None = None,
                  label: str = FREQUENCY_LABEL) -> list[Dimension]:
    """The ``layout.dim`` of a vector message: ``(label, N, N)``, ``sample:<n>``, ``run:<id>``.

    The sample and run dims are left out when None; a run needs an index (else left out).

    Raises:
        ValueError: an index < 0 or a run id out of range.
    """
    dims = [(label, size, size)]
    if sample_index is not None:
        dims.append((sample_label(sample_index), 1, 1))
        if run is not None:
            dims.append((run_label(run), 1, 1))
    return dims


def weights_layout(tones: int, struts: int, sample_index: int) -> list[Dimension]:
    """The ``layout.dim`` of ``/pph/notch_weights``: tone, strut, (a, b), ``sample:<n>``."""
    return [("tone", tones, tones * 2 * struts), ("strut", struts, 2 * struts),
            ("a_b", 2, 2), (sample_label(sample_index), 1, 1)]


def encode_float64_array(values: np.ndarray | Sequence[float],
                         dims: Sequence[Dimension]) -> bytes:
    """The serialized (little-endian CDR) Float64MultiArray of ``values`` with ``dims``.

    What rclpy serializes from the same message (tested): for the messages published
    every sample or of many values (the controllers' forecasts, 1 200 values every 10
    samples: about 59 us through the Python message, a few here). One exception, by the
    CDR standard (OMG CDR 9.3.2.5; eProsima/Fast-CDR#6): an empty ``data`` has no
    alignment padding after its length, where Jazzy's Fast CDR writes 4 bytes when the
    length ends off an 8-byte boundary. rclpy reads both; rosbags refuses the padded one
    ("CDR message size mismatch"), so a bag of empty reports (``/pph/notch_held``,
    ``/pph/stand_ins``) would not open in it.
    """
    flat = np.ascontiguousarray(values, dtype="<f8").reshape(-1)
    head = b"".join((CDR_LE, b"\x00\x00", _LE32.pack(len(dims)),
                     *(cdr_string(label.encode()) + struct.pack("<II", size, stride)
                       for label, size, stride in dims),
                     _LE32.pack(0), _LE32.pack(flat.size)))
    if not flat.size:
        return head
    return b"".join((head, _ALIGN8[(CDR_HEADER - len(head)) & 7], flat.tobytes()))


def encode_vector_cdr(values: np.ndarray | Sequence[float], sample_index: int | None,
                      run: int | None = None, label: str = FREQUENCY_LABEL) -> bytes:
    """The bytes of ``messages.make_vector_array(values, sample_index, run, label)``."""
    flat = np.ascontiguousarray(values, dtype="<f8").reshape(-1)
    return encode_float64_array(flat, vector_layout(flat.size, sample_index, run, label))


def encode_weights_cdr(weights: np.ndarray, sample_index: int) -> bytes:
    """The bytes of ``messages.make_weights_array(weights, sample_index)`` ((T, C) complex)."""
    return encode_float64_array(weights_data(weights), weights_layout(*weights.shape,
                                                                      sample_index))


def weights_data(weights: np.ndarray) -> np.ndarray:
    """The data of ``/pph/notch_weights``: (a, b) per tone and strut of W = a - j b (N)."""
    return np.stack([weights.real, -weights.imag], axis=-1).ravel()


_STAMP_CDR = struct.Struct("<4siI")     # encapsulation (LE CDR), sec (int32), nanosec


def stamp_cdr(sec: int, nanosec: int) -> bytes:
    """The encapsulation and a ``builtin_interfaces/Time`` (``sec`` s, ``nanosec`` ns).

    A whole /clock message, and the start of one whose first field is a stamp (a
    ``std_msgs/Header``'s: ``diagnostics_cdr``).
    """
    return _STAMP_CDR.pack(CDR_LE + b"\x00\x00", sec, nanosec)


def clock_cdr(sample: int, sample_rate_hz: float = SAMPLE_RATE_HZ) -> bytes:
    """``rosgraph_msgs/Clock`` at the sim time of loop sample ``sample`` as CDR bytes.

    What rclpy serializes from a ``Clock`` at ``sample_sim_time(sample)`` (tested), built
    without the Python message: the driver publishes it every sample.
    """
    return stamp_cdr(*sample_sim_time(sample, sample_rate_hz))


# ---------------------------------------------------------------------------- reading
class UnsupportedCdr(InvalidStrutMessage):
    """Bytes that are not a Float64MultiArray in plain CDR: truncated, garbage, other encoding."""


def decode_strut_cdr(raw: bytes, count: int = STRUT_COUNT) -> StrutSample:
    """The six values, sample index and run of a serialized ``/pph/*`` message.

    ``count``: the number of values the topic carries (6 on the strut topics; 1 on
    ``/pph/reference_frequency``).

    Reads plain CDR (XCDR1) in either byte order without building the Python message
    (a few microseconds against about 19 us for rclpy's conversion; a loop message as
    :func:`encode_strut_cdr` writes it is read at its fixed offsets), with the rules of
    ``messages.parse_strut_array``, and refuses anything that is not exactly one
    well-formed ``Float64MultiArray``: every length is checked against the bytes, at most
    :data:`MAX_LAYOUT_DIMS` dims, and the data must end the message.

    Raises:
        UnsupportedCdr: Another encapsulation, truncated or trailing bytes, an impossible
            layout or a label that is not UTF-8.
        InvalidStrutMessage: Not six values, a non-finite value, a bad sample or run label.
    """
    raw = bytes(raw)
    if count == STRUT_COUNT:
        return _read_loop_message(raw) or _decode_strut_by_walk(raw, count)
    return _decode_strut_by_walk(raw, count)


def _decode_strut_by_walk(raw: bytes, count: int) -> StrutSample:
    """:func:`decode_strut_cdr` of any bytes: the layout walked, every rule checked."""
    order = _BYTE_ORDER.get(raw[:2])
    if order is None or len(raw) < CDR_HEADER + 12:
        raise UnsupportedCdr(f"not a plain CDR Float64MultiArray ({len(raw)} bytes, "
                             f"encapsulation {raw[:2].hex()})")
    u32 = _U32[order]
    try:
        pos, labels = _read_layout(raw, u32, _LOOP_LABELS)
        (received,) = u32.unpack_from(raw, pos)
    except (struct.error, UnicodeDecodeError) as exc:
        raise UnsupportedCdr(f"malformed Float64MultiArray CDR: {exc}") from None
    if received != count:
        kind = "strut values" if count == STRUT_COUNT else "value(s)"
        raise InvalidStrutMessage(f"expected {count} {kind}, got {received}")
    pos += 4
    pos += -(pos - CDR_HEADER) % 8                         # float64 alignment
    if not 0 <= len(raw) - (pos + 8 * count) <= 3:
        raise UnsupportedCdr(f"malformed Float64MultiArray CDR: {len(raw)} bytes for "
                             f"{pos + 8 * count}")
    values = np.frombuffer(raw, dtype=order + "f8", count=count, offset=pos)
    if order == ">":
        values = values.astype(np.float64)
        values.flags.writeable = False
    if not all(map(math.isfinite, values.tolist())):
        raise InvalidStrutMessage(f"non-finite strut value in {values.tolist()}")
    index, run = parse_layout_labels(labels)
    return StrutSample(values, index, run)


def _read_loop_message(raw: bytes) -> StrutSample | None:
    """The sample of exactly the bytes :func:`encode_strut_cdr` writes with a run, else None.

    The driver's and controllers' messages, read at a fraction of the walk's cost: the two
    labels' digits are read where that layout has them, the head those numbers give
    (:func:`_loop_head`) must equal the bytes, and six finite values end them. Anything else
    (another layout or byte order, a label written otherwise, an index or a run out of
    range, a non-finite value) is None: the walk then reads or refuses it, so every answer
    is the walk's.
    """
    if not raw.startswith(_PREFIX[3]):
        return None
    end = raw.find(0, _SAMPLE_AT, _SAMPLE_AT + _SAMPLE_DIGITS + 1)
    digits = raw[_SAMPLE_AT:end]
    run_at = _RUN_AT + ((len(digits) + 3) & ~3)
    run_end = raw.find(0, run_at, run_at + _RUN_DIGITS + 1)
    run_digits = raw[run_at:run_end]
    if not (end > 0 < run_end and digits.isdigit() and run_digits.isdigit()):
        return None
    index, run = int(digits), int(run_digits)
    if index > MAX_SAMPLE_INDEX or not 1 <= run <= MAX_RUN_ID:
        return None
    head = _loop_head(index, run)
    data_at = len(head) + ((CDR_HEADER - len(head)) & 7)
    if len(raw) != data_at + 8 * STRUT_COUNT or not raw.startswith(head):
        return None
    values = np.frombuffer(raw, "<f8", STRUT_COUNT, data_at)
    if not all(map(math.isfinite, values.tolist())):
        return None
    return StrutSample(values, index, run)


def decode_float64_array(raw: bytes, max_values: int = MAX_ARRAY_VALUES
                         ) -> tuple[np.ndarray, list[str]]:
    """Values and every dimension label of a little-endian CDR Float64MultiArray.

    Laxer than :func:`decode_strut_cdr`, as a bag's other topics need: any number of
    values up to ``max_values``, bytes after the data ignored, labels not
    interpreted (each one must still be a terminated UTF-8 string inside the bytes).

    Raises:
        UnsupportedCdr: Not little-endian CDR, an impossible layout, values beyond the bytes.
        struct.error, UnicodeDecodeError: Truncated bytes, a label that is not UTF-8.
    """
    if raw[:2] not in LITTLE_ENDIAN_CDR:
        raise UnsupportedCdr(f"not little-endian CDR (encapsulation {bytes(raw[:2]).hex()})")
    pos, labels = _read_layout(raw, _LE32, _EVERY_LABEL)
    (count,) = _LE32.unpack_from(raw, pos)
    pos += 4
    if count:                       # an empty sequence has no alignment (CDR; Fast CDR pads)
        pos += -(pos - CDR_HEADER) % 8
    if count > max_values or pos + 8 * count > len(raw):
        raise UnsupportedCdr(f"{count} values in {len(raw)} bytes")
    return np.frombuffer(raw, "<f8", count, pos).astype(np.float64), labels


def _read_layout(raw: bytes, u32: struct.Struct, decoded: Container[int]
                 ) -> tuple[int, list[str]]:
    """Walk ``layout`` (dims, data_offset) of ``raw``: the offset of ``data`` and the labels.

    Only the labels of the dims in ``decoded`` are decoded (UTF-8); "" stands in for the
    others.

    Raises:
        UnsupportedCdr: More than :data:`MAX_LAYOUT_DIMS` dims, a string beyond the bytes
            or not NUL-terminated.
        struct.error: The bytes end inside a length field.
        UnicodeDecodeError: A decoded label that is not UTF-8.
    """
    (dims,) = u32.unpack_from(raw, CDR_HEADER)
    if dims > MAX_LAYOUT_DIMS:
        raise UnsupportedCdr(f"impossible layout: {dims} dims")
    pos, labels, size = CDR_HEADER + 4, [], len(raw)
    for d in range(dims):
        (length,) = u32.unpack_from(raw, pos)              # string length incl. NUL
        end = pos + 4 + length
        if length < 1 or end > size or raw[end - 1] != 0:
            raise UnsupportedCdr(f"bad string of length {length} in layout.dim[{d}]")
        labels.append(raw[pos + 4:end - 1].decode() if d in decoded else "")
        pos = end + (-(end - CDR_HEADER) % 4) + 8          # align, then size and stride
    return pos + 4, labels                                  # data_offset (uint32)


def sample_index_of_cdr(data: bytes | memoryview) -> int | None:
    """The ``sample:<n>`` index of any serialized Float64MultiArray (little-endian CDR).

    Looks at the layout's labels only (any dimension), so it serves the strut topics and
    ``/pph/notch_weights`` alike; None when there is none or the bytes are not that.
    A loop message (``strut`` then ``sample:<n>``) is read at its fixed offsets, the same
    answer at a fraction of the walk's cost (the recorder asks for every loop message).
    """
    raw = bytes(data[:512])
    if (raw[_DIM0] == _STRUT_DIM0 and raw[_SAMPLE_PREFIX_BYTES] == _SAMPLE_PREFIX
            and raw[:2] in LITTLE_ENDIAN_CDR and raw[_DIMS] not in _UNDER_2):
        (length,) = _LE32.unpack_from(raw, _SAMPLE_LENGTH_AT)
        if length < len(_SAMPLE_PREFIX) + 1:       # the label ends before its prefix does
            return _sample_index_by_walk(raw)
        digits = raw[_SAMPLE_AT:_SAMPLE_LENGTH_AT + 3 + length]     # its NUL left out
        if not (len(digits) <= _SAMPLE_DIGITS and digits.isdigit()):   # ASCII digits only
            return None
        index = int(digits)
        return index if index < _INDEX_LIMIT else None
    return _sample_index_by_walk(raw)


def _sample_index_by_walk(raw: bytes) -> int | None:
    """:func:`sample_index_of_cdr` of any layout: every label is looked at in turn."""
    if raw[:2] not in LITTLE_ENDIAN_CDR:
        return None
    try:
        pos = CDR_HEADER
        (ndims,) = _LE32.unpack_from(raw, pos)
        pos += 4
        for _ in range(min(ndims, MAX_LAYOUT_DIMS)):
            (length,) = _LE32.unpack_from(raw, pos)
            pos += 4
            label = raw[pos:pos + length - 1]
            if label.startswith(_SAMPLE_PREFIX):
                index = parse_sample_label(label.decode("ascii"))
                return index if index < MAX_BAG_SAMPLE_INDEX else None
            pos += length
            pos += (-(pos - CDR_HEADER)) % 4 + 8
    except (struct.error, UnicodeDecodeError, InvalidStrutMessage):
        return None
    return None
