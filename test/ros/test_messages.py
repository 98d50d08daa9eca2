"""Tests of hexapod_vibration.ros.messages on real std_msgs messages (CDR round trips included).

The serialized (CDR) path is tested in test_rclpy_internals.py.
"""

import math

import numpy as np
import pytest
from node_graph import float64_array
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import STRUT_COUNT
from hexapod_vibration.ros.messages import (
    InvalidStrutMessage,
    make_strut_array,
    parse_strut_array,
    parse_strut_sample,
)

VALUES = np.array([1.5, -2.25, 3.0e-7, 9.80665, -1.0e3, 0.0])


def _round_trip(msg: Float64MultiArray) -> Float64MultiArray:
    return deserialize_message(serialize_message(msg), Float64MultiArray)




def test_layout_with_sample_index():
    msg = make_strut_array(VALUES, 42)
    dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
    assert dims == [("strut", 6, 6), ("sample:42", 1, 1)]
    assert list(msg.data) == VALUES.tolist()


def test_layout_without_sample_index():
    msg = make_strut_array(VALUES.tolist(), None)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == [("strut", 6, 6)]


@pytest.mark.parametrize("index", [0, 1, 999, 2**40])
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
    values, parsed = parse_strut_array(float64_array(VALUES, []))
    assert parsed is None
    np.testing.assert_array_equal(values, VALUES)


def test_parsed_values_are_read_only():
    values, _ = parse_strut_array(_round_trip(make_strut_array(VALUES, 3)))
    with pytest.raises(ValueError):
        values[0] = 1.0


def test_make_accepts_column_vector():
    msg = make_strut_array(VALUES.reshape(6, 1), 5)
    np.testing.assert_array_equal(parse_strut_array(msg)[0], VALUES)


@pytest.mark.parametrize("count", [0, 5, 7, 12])
def test_make_rejects_wrong_length(count):
    with pytest.raises(ValueError, match="expected 6 strut values"):
        make_strut_array(np.zeros(count), 1)


def test_make_rejects_negative_index():
    with pytest.raises(ValueError, match=">= 0"):
        make_strut_array(VALUES, -1)


@pytest.mark.parametrize("count", [0, 5, 7])
def test_parse_rejects_wrong_length(count):
    msg = float64_array(np.zeros(count), [("strut", count, count), ("sample:3", 1, 1)])
    with pytest.raises(InvalidStrutMessage, match=f"expected 6 strut values, got {count}"):
        parse_strut_array(msg)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_parse_rejects_non_finite(bad):
    data = VALUES.copy()
    data[4] = bad
    with pytest.raises(InvalidStrutMessage, match="non-finite"):
        parse_strut_array(_round_trip(make_strut_array(data, 8)))


@pytest.mark.parametrize(
    "label",
    [
        "sample:",
        "sample:-3",
        "sample:+3",
        "sample: 3",
        "sample:3.0",
        "sample:1_000",
        "sample:٣",
        "Sample:3",
        "samples:3",
        "time:3",
        "",
    ],
)
def test_parse_rejects_garbled_sample_label(label):
    msg = _round_trip(float64_array(VALUES, [("strut", 6, 6), (label, 1, 1)]))
    with pytest.raises(InvalidStrutMessage, match="label"):
        parse_strut_array(msg)


def test_invalid_message_is_a_value_error():
    assert issubclass(InvalidStrutMessage, ValueError)


def test_layout_with_sample_index_and_run():
    msg = make_strut_array(VALUES, 42, 7)
    dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
    assert dims == [("strut", 6, 6), ("sample:42", 1, 1), ("run:7", 1, 1)]
    assert len(msg.data) == 6
    sample = parse_strut_sample(_round_trip(msg))
    assert (sample.index, sample.run) == (42, 7)
    with pytest.raises(ValueError, match="needs a sample index"):
        make_strut_array(VALUES, None, 7)
