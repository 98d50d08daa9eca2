"""What the driver publishes every sample: /clock, the tachometer, the sensors, the force.

(In realtime its reports on the commands it applied are
:mod:`~hexapod_vibration.nodes.driver_reports`'.)

:class:`DriverOutputs` owns the driver's loop publishers (watched for their matched
readers, :mod:`hexapod_vibration.ros.matching`). The sample's /clock and sensor messages are
encoded once (CDR bytes) and published again as they are when lockstep re-offers the sample.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.cdr import clock_cdr, encode_vector_cdr
from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
)
from hexapod_vibration.core.model.plant import PlantSample
from hexapod_vibration.ros.matching import MatchedReaders
from hexapod_vibration.ros.messages import StrutArrayPublisher
from hexapod_vibration.ros.qos import CLOCK_QOS, LOOP_PUBLISHER_QOS
from hexapod_vibration.ros.rclpy_internals import serialized_publish

LOOP_TOPICS = ("/pph/accel", "/pph/eddy", "/pph/actuator_force", REFERENCE_FREQUENCY_TOPIC,
               DISTURBANCE_FREQUENCIES_TOPIC)


class DriverOutputs:
    """The driver's loop publishers and the current sample's encoded messages.

    Args:
        node: The driver node.
        sample_rate_hz: Loop rate (Hz), for /clock.
        on_matched: Called when a loop publisher's matched readers change.
        defer_force: Publish a sample's applied force after the next sample's sensors
            (realtime: the force is for the recorder, the sensors are on the controllers'
            deadline), not at once.
    """

    def __init__(self, node: Node, sample_rate_hz: float,
                 on_matched: Callable[[], None], defer_force: bool = False) -> None:
        """Create the publishers."""
        self.fs = sample_rate_hz
        self.defer_force = defer_force
        self._pending_force: bytes | None = None
        self.readers = MatchedReaders(on_matched)
        arrays = {topic: self.readers.publisher(node, Float64MultiArray, topic,
                                                LOOP_PUBLISHER_QOS) for topic in LOOP_TOPICS}
        self._accel = StrutArrayPublisher(arrays["/pph/accel"])
        self._eddy = StrutArrayPublisher(arrays["/pph/eddy"])
        self._force = StrutArrayPublisher(arrays["/pph/actuator_force"])
        self._reference = serialized_publish(arrays[REFERENCE_FREQUENCY_TOPIC])
        self._frequencies = serialized_publish(arrays[DISTURBANCE_FREQUENCIES_TOPIC])
        self._clock = serialized_publish(self.readers.publisher(node, Clock, "/clock",
                                                                CLOCK_QOS))
        self._offer: tuple[bytes, bytes, bytes] | None = None
        self._reference_msg: bytes | None = None

    def offer(self, n: int, run: int, sensors: PlantSample,
              reference_hz: float | None) -> None:
        """Encode and publish sample ``n``'s /clock, tachometer (Hz, None: off) and sensors."""
        self._offer = (clock_cdr(n, self.fs), self._accel.encode(sensors.accel_m_s2, n, run),
                       self._eddy.encode(sensors.eddy_m, n, run))
        self._reference_msg = (None if reference_hz is None
                               else encode_vector_cdr([reference_hz], n, run))
        self.offer_again()
        self.flush_force()

    def offer_again(self) -> None:
        """Publish the current sample's messages again, as they were."""
        clock, accel, eddy = self._offer
        if self._reference_msg is not None:
            self._reference(self._reference_msg)
        self._clock(clock)
        self._accel.publish_bytes(accel)
        self._eddy.publish_bytes(eddy)

    def force(self, applied_n, n: int, run: int) -> None:
        """Publish the force (N) applied over sample ``n`` (deferred: with the next sensors)."""
        if not self.defer_force:
            self._force.publish(applied_n, n, run)
            return
        self.flush_force()
        self._pending_force = self._force.encode(applied_n, n, run)

    def flush_force(self) -> None:
        """Publish the deferred force, if one waits (after the sensors; at exit)."""
        if self._pending_force is not None:
            self._force.publish_bytes(self._pending_force)
            self._pending_force = None

    def frequencies(self, frequencies_hz, n: int, run: int) -> None:
        """Publish the true frequency (Hz) of every sounding tone at sample ``n``."""
        self._frequencies(encode_vector_cdr(frequencies_hz, n, run))
