"""The loop's hand-written CDR (hexapod_vibration.cdr) against rclpy's own serializer.

And hostile bytes, refused without an exception: rclpy's deserializer raises ``RMWError``
on some of them and decodes others into garbage.
"""

import math
import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from node_graph import float64_array
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration import cdr as cdr_module
from hexapod_vibration.cdr import (
    MAX_ARRAY_VALUES,
    MAX_BAG_SAMPLE_INDEX,
    MAX_LAYOUT_DIMS,
    UnsupportedCdr,
    clock_cdr,
    decode_float64_array,
    decode_strut_cdr,
    encode_float64_array,
    encode_strut_cdr,
    encode_vector_cdr,
    encode_weights_cdr,
    sample_index_of_cdr,
)
from hexapod_vibration.contract import (
    MAX_RUN_ID,
    MAX_SAMPLE_INDEX,
    InvalidStrutMessage,
    sample_label,
    sample_sim_time,
)
from hexapod_vibration.ros.messages import (
    make_strut_array,
    make_vector_array,
    make_weights_array,
    parse_strut_array,
    parse_strut_sample,
    receive_strut_array,
    receive_strut_sample,
)

VALUES = np.array([1.5, -2.25, 3.0e-7, 9.80665, -1.0e3, 0.0])
RUN = 1234567890123




class _Logger:
    """Collects warnings as rclpy's logger would print them."""

    def __init__(self):
        self.warnings: list[str] = []

    def warn(self, text: str, **_kwargs) -> None:
        self.warnings.append(text)


LABELS = ["", "s", "strut", "x" * 7, "dim with spaces", "ü-label"]


# ------------------------------------------------------------------ against rclpy
@pytest.mark.parametrize("run", [None, 1, RUN])
@pytest.mark.parametrize("index", [0, 1, 9, 10, 12345, MAX_SAMPLE_INDEX, None])
@pytest.mark.parametrize("first_label", LABELS)
def test_decode_cdr_equals_parse_of_rclpy_deserialization(index, first_label, run):
    """Every label length (string padding) and index width, against rclpy's own CDR."""
    msg = make_strut_array(VALUES, index, run if index is not None else None)
    msg.layout.dim[0].label = first_label
    msg.layout.data_offset = 3
    raw = serialize_message(msg)
    values, decoded, decoded_run = decode_strut_cdr(raw)
    expected = parse_strut_sample(deserialize_message(raw, Float64MultiArray))
    np.testing.assert_array_equal(values, expected.values)
    assert decoded == expected.index == index
    assert decoded_run == expected.run == (run if index is not None else None)


@pytest.mark.parametrize("dims", [[], [("strut", 6, 6)], [("a", 6, 6), ("sample:4", 1, 1),
                                                          ("extra", 1, 1)]])
def test_decode_cdr_reads_other_layouts_like_parse(dims):
    raw = serialize_message(float64_array(VALUES, dims))
    values, index, run = decode_strut_cdr(raw)
    np.testing.assert_array_equal(values, VALUES)
    assert index == (4 if len(dims) > 1 else None)
    assert run is None


@pytest.mark.parametrize("data, dims, reason", [
    (VALUES[:5], [("strut", 6, 6)], "expected 6"),
    (np.append(VALUES, 1.0), [("strut", 6, 6)], "expected 6"),
    ([], [], "expected 6"),
    ([1, 2, math.nan, 4, 5, 6], [("strut", 6, 6)], "non-finite"),
    ([1, 2, 3, -math.inf, 5, 6], [("strut", 6, 6)], "non-finite"),
    (VALUES, [("strut", 6, 6), ("sample:-1", 1, 1)], "garbled"),
    (VALUES, [("strut", 6, 6), ("frame:3", 1, 1)], "sample"),
    (VALUES, [("strut", 6, 6), ("sample:99999999999999999999", 1, 1)], "out of range"),
    (VALUES, [("strut", 6, 6), (f"sample:{MAX_SAMPLE_INDEX + 1}", 1, 1)], "out of range"),
    (VALUES, [("strut", 6, 6), ("sample:3", 1, 1), ("run:0", 1, 1)], "run"),
    (VALUES, [("strut", 6, 6), ("sample:3", 1, 1), ("run:x", 1, 1)], "run"),
])
def test_decode_cdr_rejects_what_parse_rejects(data, dims, reason):
    raw = serialize_message(float64_array(data, dims))
    with pytest.raises(InvalidStrutMessage, match=reason):
        decode_strut_cdr(raw)
    with pytest.raises(InvalidStrutMessage, match=reason):
        parse_strut_array(deserialize_message(raw, Float64MultiArray))


def test_truncated_or_foreign_bytes_are_unsupported_not_misread():
    raw = serialize_message(make_strut_array(VALUES, 77, RUN))
    for cut in range(len(raw) - 1):
        try:
            values, index, run = decode_strut_cdr(raw[:cut])
        except InvalidStrutMessage:
            continue
        pytest.fail(f"{cut} bytes decoded as {values}, {index}, {run}")
    big_endian = b"\x00\x00" + raw[2:]
    with pytest.raises(UnsupportedCdr):
        decode_strut_cdr(big_endian)


def _big_endian_bytes(index: int) -> bytes:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg = store.types["std_msgs/msg/Float64MultiArray"](
        layout=store.types["std_msgs/msg/MultiArrayLayout"](
            dim=[store.types["std_msgs/msg/MultiArrayDimension"](label=lbl, size=s, stride=s)
                 for lbl, s in (("strut", 6), (f"sample:{index}", 1), (f"run:{RUN}", 1))],
            data_offset=0),
        data=VALUES.copy())
    return bytes(store.serialize_cdr(msg, "std_msgs/msg/Float64MultiArray",
                                     little_endian=False))


def test_big_endian_cdr_is_read_as_rclpy_reads_it():
    """Another DDS vendor may send big-endian CDR: decoded here, the result is rclpy's."""
    raw = _big_endian_bytes(31)
    expected = parse_strut_sample(deserialize_message(raw, Float64MultiArray))
    values, index, run = decode_strut_cdr(raw)
    np.testing.assert_array_equal(values, expected.values)
    assert values.dtype == np.float64 and not values.flags.writeable
    assert (index, run) == (expected.index, expected.run) == (31, RUN)
    logger = _Logger()
    values, index = receive_strut_array(raw, logger, "/pph/accel")
    np.testing.assert_array_equal(values, VALUES)
    assert index == 31 and not logger.warnings


@pytest.mark.parametrize("index", [0, 1, 9, 10, 99, 100, 12345, MAX_SAMPLE_INDEX])
@pytest.mark.parametrize("run", [None, 1, 7, RUN, 2**63 - 1])
def test_encode_cdr_is_what_rclpy_serializes(index, run):
    """Deserialized by rclpy, the bytes are make_strut_array's message; they decode back."""
    values = VALUES * (index % 1000 + 1)
    raw = encode_strut_cdr(values, index, run)
    assert deserialize_message(raw, Float64MultiArray) == make_strut_array(values, index, run)
    assert len(raw) == len(serialize_message(make_strut_array(values, index, run)))
    decoded, decoded_index, decoded_run = decode_strut_cdr(raw)
    np.testing.assert_array_equal(decoded, values)
    assert (decoded_index, decoded_run) == (index, run)


@pytest.mark.parametrize("values, index, run", [(np.zeros(5), 1, None), (np.zeros(7), 1, None),
                                                (np.zeros(6), -1, None), (np.zeros(6), 1, 0)])
def test_encode_cdr_rejects_bad_input(values, index, run):
    with pytest.raises(ValueError):
        encode_strut_cdr(values, index, run)


@pytest.mark.parametrize("sample", [0, 1, 999, 1000, 1001, 123456789, 2**40])
def test_clock_bytes_are_what_rclpy_serializes(sample):
    sec, nanosec = sample_sim_time(sample)
    expected = Clock(clock=Time(sec=sec, nanosec=nanosec))
    raw = clock_cdr(sample)
    assert raw == serialize_message(expected)
    assert deserialize_message(raw, Clock) == expected


# ------------------------------------------------------------------ hostile bytes
def _hostile_bytes() -> dict[str, bytes]:
    raw = encode_strut_cdr(np.arange(1.0, 7.0), 77, RUN)
    cases = {
        "truncated_by_8": raw[:-8],
        "truncated_at_half": raw[:len(raw) // 2],
        "header_only": raw[:4],
        "empty": b"",
        "ff_garbage": b"\xff" * len(raw),
        "big_endian_header": b"\x00\x00" + raw[2:],
        "trailing_garbage": raw + b"\x01" * 8,
        "xcdr2_header": b"\x00\x07" + raw[2:],
    }
    for name, dims in (("huge_dims_count", 0xFFFFFFFF), ("dims_beyond_max", MAX_LAYOUT_DIMS + 1),
                       ("one_dim_too_many", 4)):
        bad = bytearray(raw)
        bad[4:8] = struct.pack("<I", dims)
        cases[name] = bytes(bad)
    bad = bytearray(raw)
    bad[8:12] = struct.pack("<I", 0xFFFFFFF0)          # dim[0] label length
    cases["huge_label_length"] = bytes(bad)
    bad = bytearray(raw)
    bad[-52:-48] = struct.pack("<I", 7)                 # data length beyond the bytes
    cases["data_length_beyond_bytes"] = bytes(bad)
    cases["big_endian_truncated"] = _big_endian_bytes(31)[:-8]
    return cases


HOSTILE = _hostile_bytes()


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_bytes_are_refused_without_an_exception(name):
    """Where rclpy's deserializer would raise RMWError (crashing the node) or decode garbage."""
    logger = _Logger()
    assert receive_strut_sample(HOSTILE[name], logger, "/pph/accel") is None
    assert receive_strut_array(HOSTILE[name], logger, "/pph/accel") is None
    assert len(logger.warnings) == 2 and "/pph/accel" in logger.warnings[0]
    with pytest.raises(InvalidStrutMessage):
        decode_strut_cdr(HOSTILE[name])


def test_the_data_length_case_hits_the_length_field():
    """The hostile case above edits the data length, not some other field."""
    raw = encode_strut_cdr(np.arange(1.0, 7.0), 77, RUN)
    assert struct.unpack("<I", raw[-52:-48]) == (6,)


# ------------------------------------------------------------------ a bag's arrays
def _rosbags_array(values, dims, little_endian=True) -> bytes:
    """A Float64MultiArray serialized by rosbags (what a bag holds), any layout."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    t = store.types
    msg = t["std_msgs/msg/Float64MultiArray"](
        layout=t["std_msgs/msg/MultiArrayLayout"](
            dim=[t["std_msgs/msg/MultiArrayDimension"](label=lbl, size=s, stride=s)
                 for lbl, s in dims], data_offset=0),
        data=np.asarray(values, np.float64))
    return bytes(store.serialize_cdr(msg, "std_msgs/msg/Float64MultiArray",
                                     little_endian=little_endian))


@pytest.mark.parametrize("count", [0, 1, 3, 12, MAX_ARRAY_VALUES])
def test_a_bag_array_is_read_with_every_label(count):
    values = np.arange(count) * 0.5
    for label in ("frequency_hz", "held:first_due,last_due,applied,gain"):     # both alignments
        dims = [(label, count), ("sample:12", 1), ("run:3", 1), ("sample:99", 1)]
        raw = _rosbags_array(values, dims)
        for trailing in (b"", b"\x00" * 8):            # bytes after the data are ignored
            decoded, labels = decode_float64_array(raw + trailing)
            np.testing.assert_array_equal(decoded, values)
            assert labels == [label for label, _ in dims]


@pytest.mark.parametrize("name, raw", [
    ("too_many_values", _rosbags_array(np.zeros(MAX_ARRAY_VALUES + 1), [("x", 65)])),
    ("big_endian", _rosbags_array(np.zeros(6), [("strut", 6)], little_endian=False)),
    ("dims_beyond_max", _rosbags_array(np.zeros(6), [("d", 1)] * (MAX_LAYOUT_DIMS + 1))),
    ("values_beyond_bytes", _rosbags_array(np.zeros(6), [("strut", 6)])[:-1]),
    ("label_not_utf8", _rosbags_array(np.zeros(6), [("strut", 6)]).replace(b"strut", b"st\xffut")),
])
def test_a_bag_array_that_is_not_one_is_refused(name, raw):
    with pytest.raises((ValueError, struct.error)):
        decode_float64_array(raw)


def test_the_sample_index_is_found_in_any_dimension():
    weights = _rosbags_array(np.zeros(24), [("tone", 2), ("strut", 6), ("ab", 2),
                                            ("sample:4567", 1)])
    assert sample_index_of_cdr(weights) == 4567
    assert sample_index_of_cdr(encode_strut_cdr(VALUES, 77, RUN)) == 77
    assert sample_index_of_cdr(_rosbags_array(VALUES, [("strut", 6)])) is None
    assert sample_index_of_cdr(_rosbags_array(VALUES, [("strut", 6), ("sample:12", 1)],
                                              little_endian=False)) is None
    assert sample_index_of_cdr(b"\x00\x01\x00\x00" + b"\xff" * 40) is None
    assert sample_index_of_cdr(encode_strut_cdr(VALUES, MAX_BAG_SAMPLE_INDEX, RUN)) is None
    assert sample_index_of_cdr(encode_strut_cdr(VALUES, MAX_BAG_SAMPLE_INDEX - 1)) == (
        MAX_BAG_SAMPLE_INDEX - 1)


def _label_bytes(label: bytes) -> bytes:
    """A CDR string at a 4-aligned position: length (NUL included), bytes, NUL, padding."""
    return struct.pack("<I", len(label) + 1) + label + bytes(1 + (-(len(label) + 1) % 4))


def test_a_loop_message_read_at_its_offsets_gives_the_walk_s_answer():
    """The fixed-offset reading of a loop message answers as the walk over every label.

    Loop-shaped layouts (``strut`` first) with every sort of second label and dimension
    count, and the same bytes with one byte changed anywhere in their first 48.
    """
    seconds = [b"sample:0", b"sample:77", b"sample:" + str(MAX_SAMPLE_INDEX).encode(),
               b"sample:" + str(MAX_SAMPLE_INDEX + 1).encode(), b"sample:", b"sample:12a",
               b"sample:+5", b"sample: 5", b"sample:\xd9\xa3", b"sample:0099",
               b"sample:" + b"9" * 30, b"samples:5", b"run:5", b"sample:5\x00junk"]
    messages = []
    for dims in (0, 1, 2, 3, 17):
        for second in seconds:
            head = struct.pack("<I", dims) + _label_bytes(b"strut") + struct.pack("<II", 6, 6)
            messages.append(b"\x00\x01\x00\x00" + head + _label_bytes(second)
                            + struct.pack("<II", 1, 1) + _label_bytes(b"run:3")
                            + bytes(8) + struct.pack("<I", 6) + bytes(4) + bytes(48))
    messages.append(encode_strut_cdr(VALUES, 123456, RUN))
    for length in range(10):          # dim[1] shorter than its bytes: the walk reads on
        head = struct.pack("<I", 3) + _label_bytes(b"strut") + struct.pack("<II", 6, 6)
        messages.append(b"\x00\x01\x00\x00" + head + struct.pack("<I", length)
                        + b"sample:12\x00\x00\x00" + _label_bytes(b"sample:99") + bytes(64))
    rng = np.random.default_rng(5)
    for message in list(messages):
        for position in rng.choice(48, 6, replace=False):
            changed = bytearray(message)
            changed[position] = int(rng.integers(256))
            messages.append(bytes(changed))
    found = 0
    for message in messages:
        walked = cdr_module._sample_index_by_walk(message[:512])
        assert sample_index_of_cdr(message) == walked, message[:48]
        assert sample_index_of_cdr(memoryview(message)) == walked
        found += walked is not None
    assert 20 < found < len(messages) - 20          # both answers were asked for



def _decoded(raw: bytes, read) -> tuple:
    """What a strut decoder answers for ``raw``: the sample's parts, or the refusal."""
    try:
        sample = read(raw)
    except InvalidStrutMessage as exc:
        return type(exc), str(exc)
    return (sample.values.tobytes(), sample.values.dtype.str, sample.values.flags.writeable,
            sample.index, sample.run)


def test_a_loop_message_decoded_at_its_offsets_gives_the_walk_s_answer():
    """The fixed-offset read of a loop message (with a run) answers as the full walk.

    Every digit count of index and run, both ranges' edges and beyond, non-finite values,
    bytes added or cut at the end, and each message with one byte changed anywhere.
    """
    messages = []
    for index in (0, 7, 10, 999, 1000, 123456, 10**12, MAX_SAMPLE_INDEX, MAX_SAMPLE_INDEX + 1):
        for run in (1, 9, 10, 1234, RUN, MAX_RUN_ID, MAX_RUN_ID + 1):
            messages.append(encode_strut_cdr(VALUES, index, run))
    for bad in (math.nan, math.inf, -math.inf):
        messages.append(encode_strut_cdr(np.r_[VALUES[:5], bad], 42, 3))
    canonical = encode_strut_cdr(VALUES, 42, 3)
    messages += [canonical + bytes(k) for k in (1, 3, 4, 8)] + [canonical[:-1],
                                                                 canonical[:-8]]
    messages.append(canonical.replace(b"sample:42", b"sample:+4"))
    messages.append(canonical.replace(b"run:3", b"run:0"))
    rng = np.random.default_rng(11)
    for message in list(messages[::5]):
        for position in range(len(message)):
            changed = bytearray(message)
            changed[position] = int(rng.integers(256))
            messages.append(bytes(changed))
    fast = 0
    for message in messages:
        walked = _decoded(message, lambda raw: cdr_module._decode_strut_by_walk(raw, 6))
        assert _decoded(message, decode_strut_cdr) == walked, message
        fast += cdr_module._read_loop_message(message) is not None
    assert 50 < fast < len(messages) - 50          # both ways were taken
    with pytest.raises(InvalidStrutMessage, match="expected 1 value"):
        decode_strut_cdr(canonical, count=1)     # a one-value topic: six are refused

@pytest.mark.parametrize("size", [0, 1, 5, 6, 1200])
@pytest.mark.parametrize("index, run, label", [(None, None, "frequency_hz"),
                                               (0, None, "frequency_hz"),
                                               (12345, RUN, "forecast:sample,strut"),
                                               (7, 3, "abc"), (None, 3, "ab")])
def test_encode_vector_cdr_is_what_rclpy_serializes(size, index, run, label):
    """Every label length (alignment), size, and index/run present or not."""
    values = np.linspace(-3.0, 7.0, size)
    _assert_is_rclpy_serialization(encode_vector_cdr(values, index, run, label),
                                   make_vector_array(values, index, run, label=label))


def _assert_is_rclpy_serialization(raw: bytes, msg: Float64MultiArray) -> None:
    """Rclpy reads ``raw`` as ``msg``, and serializes ``msg`` into as many bytes.

    Not byte for byte: rclpy leaves its buffer's old bytes in the alignment padding. An
    empty ``data`` is the CDR standard's (no padding after its length, where Jazzy's Fast
    CDR pads): rclpy reads it, and so does rosbags, as a bag's reader.
    """
    assert deserialize_message(raw, Float64MultiArray) == msg
    if msg.data:
        assert len(raw) == len(serialize_message(msg))
    else:
        assert _rosbags_reads(raw).layout.dim[0].label == msg.layout.dim[0].label


def _rosbags_reads(raw: bytes):
    """The message rosbags' deserializer makes of ``raw`` (it checks the length)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(raw, "std_msgs/msg/Float64MultiArray")


def test_an_empty_array_is_the_cdr_standard_s_and_every_reader_reads_it():
    """The serializer of Jazzy's rclpy pads an empty float64 sequence; rosbags refuses that."""
    for label in ("a", "ab", "abcd", "held:first_due,last_due,applied,gain"):
        dims = [(label, 0, 0), (sample_label(123), 1, 1)]
        msg = float64_array([], dims)
        raw = encode_float64_array([], dims)
        assert deserialize_message(raw, Float64MultiArray) == msg
        assert raw == _rosbags_array([], [(label, 0), (sample_label(123), 1)])
        assert list(_rosbags_reads(raw).data) == []
        assert decode_float64_array(raw)[1] == [label, sample_label(123)]


@pytest.mark.parametrize("tones", [1, 2, 16])
def test_encode_weights_cdr_is_what_rclpy_serializes(tones):
    rng = np.random.default_rng(tones)
    weights = rng.normal(size=(tones, 6)) + 1j * rng.normal(size=(tones, 6))
    _assert_is_rclpy_serialization(encode_weights_cdr(weights, 40_001),
                                   make_weights_array(weights, 40_001))
