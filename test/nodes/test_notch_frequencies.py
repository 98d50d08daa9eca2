"""The notch node's frequency topics: estimates out, a hostile tachometer refused.

Driver and notch controller as processes (lockstep). ``/pph/notch_frequencies`` carries the
frequency of each configured tone every ``FREQUENCIES_EVERY_SAMPLES`` samples; references on
``/pph/reference_frequency`` that are not one finite value in [0, fs/2) Hz are refused with a
logged reason, and the node keeps answering every sample.
"""

from __future__ import annotations

import math

import numpy as np
from node_graph import HANG_GUARD_S, RECORD_QOS, StrutTopic, wait_until
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.contract import (
    FREQUENCIES_EVERY_SAMPLES,
    NOTCH_FREQUENCIES_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.ros.messages import make_vector_array, parse_vector_sample


def test_estimates_are_published_and_bad_references_refused(ros_context, node_processes):
    driver = node_processes.start("pph_driver", "--ros-args", "-p",
                                  "lockstep_controllers:=[notch]")
    notch = node_processes.start("notch_controller", "--ros-args",
                                 "-p", "tone_frequencies_hz:=[40.0, 80.0]",
                                 "-p", "auto_identify:=false")
    node = ros_context.create_node("frequency_listener")
    command = StrutTopic(node, "/pph/notch_command")
    received: dict[int, np.ndarray] = {}

    def on_estimates(msg: Float64MultiArray) -> None:
        sample = parse_vector_sample(msg)
        received[sample.index] = np.array(sample.values)

    node.create_subscription(Float64MultiArray, NOTCH_FREQUENCIES_TOPIC, on_estimates,
                             RECORD_QOS)
    publisher = node.create_publisher(Float64MultiArray, REFERENCE_FREQUENCY_TOPIC, 10)
    assert wait_until(ros_context, lambda: len(received) >= 20, HANG_GUARD_S), \
        driver.output() + notch.output()
    assert all(n % FREQUENCIES_EVERY_SAMPLES == 0 for n in received)
    assert all(list(v) == [40.0, 80.0] for v in received.values())

    bad = [make_vector_array([45.0, 90.0], 10), make_vector_array([math.nan], 10),
           make_vector_array([-1.0], 10), make_vector_array([600.0], 10)]
    mark = command.last_index

    def refused_and_running() -> bool:
        return (notch.output().count(f"{REFERENCE_FREQUENCY_TOPIC}: rejected") >= 1
                and command.last_index > mark + 200)

    assert wait_until(ros_context, refused_and_running, HANG_GUARD_S,
                      step=lambda: [publisher.publish(m) for m in bad]), notch.output()
    assert notch.running() and driver.running()
