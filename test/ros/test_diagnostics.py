"""Sim-time stamps and the driver's /clock bytes (hexapod_vibration.ros.diagnostics)."""

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock

from hexapod_vibration.ros.diagnostics import clock_cdr, sample_time


@pytest.mark.parametrize('sample', [0, 1, 999, 1000, 1001, 123456789, 2**40])
def test_clock_bytes_are_what_rclpy_serializes(sample):
    expected = Clock(clock=sample_time(sample))
    raw = clock_cdr(sample)
    assert raw == serialize_message(expected)
    assert deserialize_message(raw, Clock) == expected


@pytest.mark.parametrize('sample, rate, sec, nanosec', [
    (0, 1000.0, 0, 0), (1500, 1000.0, 1, 500_000_000), (-5, 1000.0, 0, 0),
    (3, 3.0, 1, 0), (1, 3.0, 0, 333_333_333)])
def test_sample_time(sample, rate, sec, nanosec):
    stamp = sample_time(sample, rate)
    assert (stamp.sec, stamp.nanosec) == (sec, nanosec)
    clock = deserialize_message(clock_cdr(sample, rate), Clock).clock
    assert (clock.sec, clock.nanosec) == (sec, nanosec)
