"""The notch controller's forecasts on the graph, and a realtime driver applying them.

Judged per sample index, never on timing: the forecast rows against the notch commands of
the same samples (lockstep, during the identification's excitation: exact), and a realtime
driver with no notch command at all, whose applied force must be a forecast's row for the
sample due wherever one covered it, and zero elsewhere.
"""

from __future__ import annotations

import numpy as np
from node_graph import Diagnostics, StrutTopic, wait_until
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    FORECAST_ROWS_LABEL,
    FORECAST_SAMPLES,
    NOTCH_FORECAST_TOPIC,
)
from hexapod_vibration.ros.command_forecasts import parse_forecast
from hexapod_vibration.ros.messages import make_vector_array
from hexapod_vibration.ros.qos import LOOP_QOS

DRIVER = "pph_driver: loop"
CHECKED_FORECASTS = 20
APPLIED_SAMPLES = 300


def test_forecast_rows_are_the_notch_commands_of_their_samples(ros_context, node_processes):
    forecasts: list = []
    node = ros_context.create_node("forecast_listener")
    node.create_subscription(Float64MultiArray, NOTCH_FORECAST_TOPIC,
                             lambda msg: forecasts.append(parse_forecast(msg)), LOOP_QOS)
    commands = StrutTopic(node, "/pph/notch_command")
    node_processes.start("pph_driver", "--ros-args", "-p", "lockstep_controllers:=[notch]")
    node_processes.start("notch_controller", "--ros-args", "-p", "tone_frequencies_hz:=[40.0]",
                         "-p", "identify_delay_s:=0.1")

    def covered() -> list:
        return [(rows, first) for rows, first, _ in forecasts
                if first > 200 and first + FORECAST_SAMPLES - 1 <= commands.last_index]
    assert wait_until(ros_context, lambda: len(covered()) >= CHECKED_FORECASTS,
                      progress=lambda: commands.last_index)
    for rows, first in covered():           # in the identification (0.1 s .. 10.1 s)
        sent = np.array([commands.by_index[first + k] for k in range(FORECAST_SAMPLES)])
        assert np.abs(sent).max() > 0.1
        np.testing.assert_allclose(rows, sent, rtol=0, atol=1e-9)


def _coded(samples: np.ndarray) -> np.ndarray:
    """A force (N) that names its sample: rows of six distinct values."""
    return (samples[:, None] % 97) * 0.1 + np.arange(6) * 0.001


def test_a_realtime_driver_applies_forecast_rows_when_no_command_comes(
        ros_context, node_processes):
    node = ros_context.create_node("forecaster")
    accel = StrutTopic(node, "/pph/accel")
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)
    publisher = node.create_publisher(Float64MultiArray, NOTCH_FORECAST_TOPIC, LOOP_QOS)
    # Without the watchdog's ramp (command_fade_samples 0): a row goes in as it is, at once
    # (the ramp, on a stream that was stale, is test_watchdog's).
    node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                         "-p", "lockstep_controllers:=[]", "-p", "command_delay_samples:=1",
                         "-p", "command_fade_samples:=0")
    sent: dict[int, np.ndarray] = {}

    def publish_ahead() -> None:
        if accel.last_index < 0:
            return
        run = next(iter(accel.by_run))
        first = accel.last_index + 20
        samples = np.arange(first, first + FORECAST_SAMPLES)
        rows = _coded(samples)
        sent.update(zip(samples.tolist(), rows, strict=True))
        publisher.publish(make_vector_array(rows.reshape(-1), first, run,
                                            label=FORECAST_ROWS_LABEL))

    def applied() -> list[int]:
        return [n for n, f in force.by_index.items() if np.any(f != 0.0)]
    assert wait_until(ros_context, lambda: len(applied()) >= APPLIED_SAMPLES,
                      step=publish_ahead, progress=lambda: force.last_index)
    for n in applied():                      # the force over n is the answer due, n - 1
        np.testing.assert_array_equal(force.by_index[n], sent[n - 1])
    unforced = [n for n, f in force.by_index.items() if n - 1 not in sent]
    assert all(not np.any(force.by_index[n]) for n in unforced)
    assert wait_until(ros_context,
                      lambda: diagnostics.int_value(DRIVER, "notch_forecast_applied")
                      >= APPLIED_SAMPLES)
