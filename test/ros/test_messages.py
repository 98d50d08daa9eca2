"""Tests of hexapod_vibration.ros.messages on real std_msgs messages (CDR round trips included)."""

import math

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from hexapod_vibration.ros.messages import (
    STRUT_COUNT,
    InvalidStrutMessage,
    UnsupportedCdr,
    decode_strut_cdr,
    encode_strut_cdr,
    make_strut_array,
    parse_strut_array,
    receive_strut_array,
)

VALUES = np.array([1.5, -2.25, 3.0e-7, 9.80665, -1.0e3, 0.0])


def _round_trip(msg: Float64MultiArray) -> Float64MultiArray:
    return deserialize_message(serialize_message(msg), Float64MultiArray)


def _message(data, dims):
    msg = Float64MultiArray()
    msg.layout.dim = [
        MultiArrayDimension(label=lbl, size=size, stride=stride) for lbl, size, stride in dims
    ]
    msg.data = [float(x) for x in data]
    return msg


def test_layout_with_sample_index():
    msg = make_strut_array(VALUES, 42)
    dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
    assert dims == [('strut', 6, 6), ('sample:42', 1, 1)]
    assert list(msg.data) == VALUES.tolist()


def test_layout_without_sample_index():
    msg = make_strut_array(VALUES.tolist(), None)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [('strut', 6, 6)]


@pytest.mark.parametrize('index', [0, 1, 999, 2**40])
def test_round_trip_through_cdr(index):
    values, parsed = parse_strut_array(_round_trip(make_strut_array(VALUES, index)))
    assert parsed == index
    assert values.dtype == np.float64
    assert values.shape == (STRUT_COUNT,)
    np.testing.assert_array_equal(values, VALUES)


def test_round_trip_without_index():
    values, parsed = parse_strut_array(_round_trip(make_strut_array(VALUES, None)))
    assert parsed is None
    np.testing.assert_array_equal(values, VALUES)


def test_message_without_layout_is_accepted():
    values, parsed = parse_strut_array(_message(VALUES, []))
    assert parsed is None
    np.testing.assert_array_equal(values, VALUES)


def test_parsed_values_are_read_only():
    values, _ = parse_strut_array(_round_trip(make_strut_array(VALUES, 3)))
    with pytest.raises(ValueError):
        values[0] = 1.0


def test_make_accepts_column_vector():
    msg = make_strut_array(VALUES.reshape(6, 1), 5)
    np.testing.assert_array_equal(parse_strut_array(msg)[0], VALUES)


@pytest.mark.parametrize('count', [0, 5, 7, 12])
def test_make_rejects_wrong_length(count):
    with pytest.raises(ValueError, match='expected 6 strut values'):
        make_strut_array(np.zeros(count), 1)


def test_make_rejects_negative_index():
    with pytest.raises(ValueError, match='>= 0'):
        make_strut_array(VALUES, -1)


@pytest.mark.parametrize('count', [0, 5, 7])
def test_parse_rejects_wrong_length(count):
    msg = _message(np.zeros(count), [('strut', count, count), ('sample:3', 1, 1)])
    with pytest.raises(InvalidStrutMessage, match=f'expected 6 strut values, got {count}'):
        parse_strut_array(msg)


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_parse_rejects_non_finite(bad):
    data = VALUES.copy()
    data[4] = bad
    with pytest.raises(InvalidStrutMessage, match='non-finite'):
        parse_strut_array(_round_trip(make_strut_array(data, 8)))


@pytest.mark.parametrize(
    'label',
    [
        'sample:',
        'sample:-3',
        'sample:+3',
        'sample: 3',
        'sample:3.0',
        'sample:1_000',
        'sample:٣',
        'Sample:3',
        'samples:3',
        'time:3',
        '',
    ],
)
def test_parse_rejects_garbled_sample_label(label):
    msg = _round_trip(_message(VALUES, [('strut', 6, 6), (label, 1, 1)]))
    with pytest.raises(InvalidStrutMessage, match='label'):
        parse_strut_array(msg)


def test_invalid_message_is_a_value_error():
    assert issubclass(InvalidStrutMessage, ValueError)


# ------------------------------------------------------------------ serialized (CDR) path
class _Logger:
    """Collects warnings as rclpy's logger would print them."""

    def __init__(self):
        self.warnings: list[str] = []

    def warn(self, text: str, **_kwargs) -> None:
        self.warnings.append(text)


LABELS = ['', 's', 'strut', 'x' * 7, 'dim with spaces', 'ü-label']


@pytest.mark.parametrize('index', [0, 1, 9, 10, 12345, 10**15, None])
@pytest.mark.parametrize('first_label', LABELS)
def test_decode_cdr_equals_parse_of_rclpy_deserialization(index, first_label):
    """Every label length (string padding) and index width, against rclpy's own CDR."""
    msg = make_strut_array(VALUES, index)
    msg.layout.dim[0].label = first_label
    msg.layout.data_offset = 3
    raw = serialize_message(msg)
    values, decoded = decode_strut_cdr(raw)
    expected_values, expected_index = parse_strut_array(deserialize_message(raw,
                                                                            Float64MultiArray))
    np.testing.assert_array_equal(values, expected_values)
    assert decoded == expected_index == index


@pytest.mark.parametrize('dims', [[], [('strut', 6, 6)], [('a', 6, 6), ('sample:4', 1, 1),
                                                          ('extra', 1, 1)]])
def test_decode_cdr_reads_other_layouts_like_parse(dims):
    raw = serialize_message(_message(VALUES, dims))
    values, index = decode_strut_cdr(raw)
    np.testing.assert_array_equal(values, VALUES)
    assert index == (4 if len(dims) > 1 else None)


@pytest.mark.parametrize('data, dims, reason', [
    (VALUES[:5], [('strut', 6, 6)], 'expected 6'),
    (np.append(VALUES, 1.0), [('strut', 6, 6)], 'expected 6'),
    ([], [], 'expected 6'),
    ([1, 2, math.nan, 4, 5, 6], [('strut', 6, 6)], 'non-finite'),
    ([1, 2, 3, -math.inf, 5, 6], [('strut', 6, 6)], 'non-finite'),
    (VALUES, [('strut', 6, 6), ('sample:-1', 1, 1)], 'garbled'),
    (VALUES, [('strut', 6, 6), ('frame:3', 1, 1)], 'sample'),
])
def test_decode_cdr_rejects_what_parse_rejects(data, dims, reason):
    raw = serialize_message(_message(data, dims))
    with pytest.raises(InvalidStrutMessage, match=reason):
        decode_strut_cdr(raw)
    with pytest.raises(InvalidStrutMessage, match=reason):
        parse_strut_array(deserialize_message(raw, Float64MultiArray))


def test_truncated_or_foreign_bytes_are_unsupported_not_misread():
    raw = serialize_message(make_strut_array(VALUES, 77))
    for cut in range(len(raw) - 1):
        try:
            values, index = decode_strut_cdr(raw[:cut])
        except (UnsupportedCdr, InvalidStrutMessage):
            continue
        pytest.fail(f'{cut} bytes decoded as {values}, {index}')
    big_endian = b'\x00\x00' + raw[2:]
    with pytest.raises(UnsupportedCdr):
        decode_strut_cdr(big_endian)


def test_receive_reads_big_endian_cdr_through_rclpy():
    """Another DDS vendor may send big-endian CDR: rclpy decodes it, the result is the same."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg = store.types['std_msgs/msg/Float64MultiArray'](
        layout=store.types['std_msgs/msg/MultiArrayLayout'](
            dim=[store.types['std_msgs/msg/MultiArrayDimension'](label=lbl, size=s, stride=s)
                 for lbl, s in (('strut', 6), ('sample:31', 1))], data_offset=0),
        data=VALUES.copy())
    raw = bytes(store.serialize_cdr(msg, 'std_msgs/msg/Float64MultiArray',
                                    little_endian=False))
    with pytest.raises(UnsupportedCdr):
        decode_strut_cdr(raw)
    logger = _Logger()
    values, index = receive_strut_array(raw, logger, '/pph/accel')
    np.testing.assert_array_equal(values, VALUES)
    assert index == 31 and not logger.warnings


def test_receive_logs_and_returns_none_for_bad_bytes():
    logger = _Logger()
    raw = serialize_message(_message([1, 2, math.nan, 4, 5, 6], [('strut', 6, 6)]))
    assert receive_strut_array(raw, logger, '/pph/eddy') is None
    assert logger.warnings and '/pph/eddy' in logger.warnings[0]


@pytest.mark.parametrize('index', [0, 1, 9, 10, 99, 100, 12345, 10**15])
def test_encode_cdr_is_what_rclpy_serializes(index):
    """Deserialized by rclpy, the bytes are make_strut_array's message; they decode back."""
    values = VALUES * (index + 1)
    raw = encode_strut_cdr(values, index)
    assert deserialize_message(raw, Float64MultiArray) == make_strut_array(values, index)
    assert len(raw) == len(serialize_message(make_strut_array(values, index)))
    decoded, decoded_index = decode_strut_cdr(raw)
    np.testing.assert_array_equal(decoded, values)
    assert decoded_index == index


@pytest.mark.parametrize('values, index', [(np.zeros(5), 1), (np.zeros(7), 1),
                                           (np.zeros(6), -1)])
def test_encode_cdr_rejects_bad_input(values, index):
    with pytest.raises(ValueError):
        encode_strut_cdr(values, index)
