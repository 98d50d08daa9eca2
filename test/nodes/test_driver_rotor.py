"""The driver's rotor: ``rotor_*`` parameters, the tachometer and the disturbance frequencies.

One driver process (realtime, no controllers) on the test's domain. Every value received
is checked against the core's :class:`~hexapod_vibration.core.model.rotor.Rotor` at the time
of the sample's sensors ((n + 1) / fs), by sample index; waits are "eventually" with a hang
guard, never timed.
"""

from __future__ import annotations

import numpy as np
import pytest
from node_graph import HANG_GUARD_S, RECORD_QOS, ParameterClient, assert_rejected, wait_until
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    FREQUENCIES_EVERY_SAMPLES,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.core.model.rotor import Rotor
from hexapod_vibration.ros.messages import parse_vector_sample

ROTOR = Rotor([1.0, 2.0], [10.0, 2.0], 40.0, [0.0, 4.0], [30.0, 34.0])


class VectorTopic:
    """Values received on a frequency topic, by sample index."""

    def __init__(self, node, topic: str):
        self.by_index: dict[int, np.ndarray] = {}
        node.create_subscription(Float64MultiArray, topic, self._on_message, RECORD_QOS)

    def _on_message(self, msg: Float64MultiArray) -> None:
        sample = parse_vector_sample(msg)
        self.by_index.setdefault(sample.index, np.array(sample.values))

    @property
    def last_index(self) -> int:
        return max(self.by_index, default=-1)


def test_tachometer_and_disturbance_frequencies_follow_the_rotor(ros_context, node_processes):
    driver = node_processes.start(
        "pph_driver", "--ros-args", "-p", "clock_mode:=realtime", "-p", "lockstep_controllers:=[]",
        "-p", "rotor_orders:=[1.0, 2.0]", "-p", "rotor_amplitudes_n:=[10.0, 2.0]",
        "-p", "rotor_reference_speed_hz:=40.0", "-p", "rotor_profile_time_s:=[0.0, 4.0]",
        "-p", "rotor_profile_speed_hz:=[30.0, 34.0]", "-p", "rotor_tachometer:=true")
    node = ros_context.create_node("rotor_listener")
    reference = VectorTopic(node, REFERENCE_FREQUENCY_TOPIC)
    truth = VectorTopic(node, DISTURBANCE_FREQUENCIES_TOPIC)
    client = ParameterClient(ros_context, node, "pph_driver")
    assert wait_until(ros_context, lambda: truth.last_index >= 1000
                      and len(reference.by_index) >= 500, HANG_GUARD_S), driver.output()

    for n, values in reference.by_index.items():
        assert values == pytest.approx([ROTOR.speed_hz((n + 1) / 1000.0)], abs=1e-12), n
    for n, values in truth.by_index.items():
        assert n % FREQUENCIES_EVERY_SAMPLES == 0
        expected = [40.0, *ROTOR.frequencies_hz((n + 1) / 1000.0)]   # shaker tone, 1x, 2x
        assert values == pytest.approx(expected, abs=1e-12), n

    # Refused with the reason, nothing changed.
    for name, bad, word in (("rotor_profile_time_s", [3.0, 1.0], "increasing"),
                            ("rotor_orders", [1.0, 20.0], "500"),
                            ("rotor_reference_speed_hz", 0.0, "minimum"),
                            ("rotor_amplitudes_n", [10.0, -1.0], "minimum")):
        before = client.get(name)[name]
        assert_rejected(client.set(name, bad), word)
        assert client.get(name)[name] == before

    # The tachometer off: no reading after the change; no rotor: the shaker tone alone.
    assert client.set("rotor_tachometer", False).successful
    assert client.set("rotor_orders", []).successful
    mark = truth.last_index
    assert wait_until(ros_context, lambda: truth.last_index > mark + 500, HANG_GUARD_S)
    assert np.all(truth.by_index[truth.last_index] == [40.0])
    assert reference.last_index < truth.last_index - 100
    assert driver.running(), driver.output()
