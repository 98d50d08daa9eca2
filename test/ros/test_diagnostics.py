"""Sim-time stamps (contract.sample_sim_time) and /clock at them.

That /clock's bytes are what rclpy serializes: test_rclpy_internals.py.
"""

import pytest
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from hexapod_vibration.cdr import clock_cdr
from hexapod_vibration.contract import sample_sim_time


@pytest.mark.parametrize("sample, rate, sec, nanosec", [
    (0, 1000.0, 0, 0), (1500, 1000.0, 1, 500_000_000), (-5, 1000.0, 0, 0),
    (3, 3.0, 1, 0), (1, 3.0, 0, 333_333_333)])
def test_sample_time(sample, rate, sec, nanosec):
    assert sample_sim_time(sample, rate) == (sec, nanosec)
    clock = deserialize_message(clock_cdr(sample, rate), Clock).clock
    assert (clock.sec, clock.nanosec) == (sec, nanosec)
