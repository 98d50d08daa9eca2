"""ControllerLoopPort, the receiving end a controller calls (ros/messages.py), on real rclpy.

The notch controller takes its /pph/accel through this port (decoding, the accelerometers'
range, runs and sequence): here the accel case is checked directly, with a real publisher
whose answers a raw subscription receives.
"""

from __future__ import annotations

import numpy as np
import pytest
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.cdr import decode_strut_cdr, encode_strut_cdr
from hexapod_vibration.core.loop.signal_ranges import SignalRanges
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.paths import config_path
from hexapod_vibration.ros.messages import ControllerLoopPort, StrutArrayPublisher
from hexapod_vibration.ros.qos import LOOP_PUBLISHER_QOS, LOOP_QOS

RANGES = SignalRanges.from_model(load_model_config(config_path("pph_model.yaml")))
GRAVITY = np.full(6, 9.80665 / np.sqrt(3.0))
RUN, OTHER_RUN = 5, 6


class _Logger:
    def __init__(self):
        self.lines: list[str] = []

    def warn(self, text: str, **_kwargs) -> None:
        self.lines.append(text)

    info = warn


@pytest.fixture
def port_and_answers(ros_context):
    node = ros_context.create_node("port_test")
    answers: list[bytes] = []
    node.create_subscription(Float64MultiArray, "/port/command", answers.append, LOOP_QOS,
                             raw=True)
    publisher = StrutArrayPublisher(node.create_publisher(Float64MultiArray, "/port/command",
                                                          LOOP_PUBLISHER_QOS))
    port = ControllerLoopPort("/pph/accel", RANGES.accel_m_s2, publisher, _Logger())
    # Discovery: publish until the subscription has one.
    assert ros_context.wait_for(lambda: answers, 30.0,
                                step=lambda: publisher.publish(np.zeros(6), 0))
    answers.clear()
    return ros_context, port, answers


def test_accel_beyond_the_accelerometer_range_is_refused(port_and_answers):
    """Regression: one 6 x 1e300 accel message took the weights to 7e298 N."""
    _, port, _ = port_and_answers
    assert port.receive(encode_strut_cdr(GRAVITY, 0, RUN)) is not None
    for values in (np.full(6, 1e300), np.full(6, 2.01 * 9.80665), np.array([0, 0, 0, 0, 0, -30.0])):
        assert port.receive(encode_strut_cdr(values, 1, RUN)) is None
    assert port.counters["out_of_range"] == 3 and port.invalid == 3
    sample = port.receive(encode_strut_cdr(np.full(6, -2.0 * 9.80665), 1, RUN))   # the clip
    assert sample is not None and sample.index == 1
    assert port.diagnostics()["out_of_range"] == 3


def test_malformed_bytes_are_counted(port_and_answers):
    _, port, _ = port_and_answers
    raw = encode_strut_cdr(GRAVITY, 0, RUN)
    for bad in (raw[:-8], raw[:4], b"\xff" * len(raw), b"\x00\x00" + raw[2:]):
        assert port.receive(bad) is None
    assert port.counters["malformed"] == 4
    assert port.receive(raw) is not None


def test_repeat_is_answered_again_with_the_same_bytes(port_and_answers):
    ros_context, port, answers = port_and_answers
    sample = port.receive(encode_strut_cdr(GRAVITY, 7, RUN))
    port.answer(np.arange(6.0), sample)
    assert port.receive(encode_strut_cdr(GRAVITY, 7, RUN)) is None       # offered again
    assert ros_context.wait_for(lambda: len(answers) >= 2, 30.0)
    assert answers[0] == answers[1]
    values, index, run = decode_strut_cdr(answers[0])
    np.testing.assert_array_equal(values, np.arange(6.0))
    assert (index, run) == (7, RUN)
    assert port.counters["repeats"] == 1


def test_new_run_is_flagged_once_confirmed(port_and_answers):
    _, port, _ = port_and_answers
    first = port.receive(encode_strut_cdr(GRAVITY, 500, RUN))
    assert first is not None and not first.new_run          # the first run: nothing to reset
    verdicts = [port.receive(encode_strut_cdr(GRAVITY, 0, OTHER_RUN)) for _ in range(3)]
    assert verdicts[:2] == [None, None]
    assert verdicts[2].new_run and verdicts[2].index == 0 and verdicts[2].run == OTHER_RUN
    assert port.counters["unconfirmed"] == 2 and port.counters["new_runs"] == 1


def test_skipped_samples_come_with_the_one_acted_on_and_only_those_before_it(port_and_answers):
    _, port, _ = port_and_answers
    assert port.receive(encode_strut_cdr(GRAVITY, 0, RUN)) is not None
    port.hold_skipped(encode_strut_cdr(GRAVITY, 1, RUN))
    port.hold_skipped(encode_strut_cdr(GRAVITY, 0, RUN))           # acted on already
    port.hold_skipped(encode_strut_cdr(GRAVITY, 2, OTHER_RUN))     # another run
    port.hold_skipped(encode_strut_cdr(np.full(6, 1e300), 2, RUN))  # out of range
    port.hold_skipped(encode_strut_cdr(GRAVITY * 2.0, 2, RUN))
    port.hold_skipped(encode_strut_cdr(GRAVITY, 3, RUN))           # the newest again
    sample = port.receive(encode_strut_cdr(GRAVITY, 3, RUN))
    assert sample.index == 3 and sample.gap == 2
    assert [s.index for s in sample.skipped] == [1, 2]
    np.testing.assert_array_equal(sample.skipped[1].values, GRAVITY * 2.0)
    assert port.counters["out_of_range"] == 1
    assert port.receive(encode_strut_cdr(GRAVITY, 4, RUN)).skipped == ()   # used once
