"""The topics ``pph_recorder`` records: name, message type and the QoS it subscribes with."""

from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterEvent
from rclpy.qos import QoSProfile
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.analysis.bag_format import (
    FREQUENCY_TOPICS,
    SENSITIVITY_TOPIC,
    STRUT_TOPICS,
    WEIGHTS_TOPIC,
)
from hexapod_vibration.contract import NOTCH_HELD_TOPIC, STAND_INS_TOPIC
from hexapod_vibration.ros.qos import (
    HELD_QOS,
    LATCHED_QOS,
    PARAMETER_EVENTS_QOS,
    RECORDER_CLOCK_QOS,
    RECORDER_QOS,
)

ARRAY_TYPE = "std_msgs/msg/Float64MultiArray"
LOOP_TOPICS = frozenset((*STRUT_TOPICS, WEIGHTS_TOPIC, *FREQUENCY_TOPICS))
"""Topics whose messages carry ``sample:<n>``: stamped n ms, one message per sample."""


REPORT_TOPICS = (NOTCH_HELD_TOPIC, STAND_INS_TOPIC)
"""A realtime driver's reports (10 Hz): the held notch commands and the stand-ins, so that
a bag can replay what the identification and the guard were told (best effort, as sent:
each report repeats the rows of the 9 before it). The forecasts
(``/pph/*_forecast``, 100 Hz x 200 rows) are not recorded: the reports say where a stand-in
went in."""


@dataclass(frozen=True)
class RecordedTopic:
    """A topic the recorder subscribes to."""

    name: str
    msg_class: type
    msgtype: str
    qos: QoSProfile


RECORDED_TOPICS: tuple[RecordedTopic, ...] = (
    *(RecordedTopic(t, Float64MultiArray, ARRAY_TYPE, RECORDER_QOS) for t in STRUT_TOPICS),
    RecordedTopic(WEIGHTS_TOPIC, Float64MultiArray, ARRAY_TYPE, RECORDER_QOS),
    *(RecordedTopic(t, Float64MultiArray, ARRAY_TYPE, RECORDER_QOS) for t in FREQUENCY_TOPICS),
    RecordedTopic(SENSITIVITY_TOPIC, Float64MultiArray, ARRAY_TYPE, LATCHED_QOS),
    *(RecordedTopic(t, Float64MultiArray, ARRAY_TYPE, HELD_QOS) for t in REPORT_TOPICS),
    RecordedTopic("/clock", Clock, "rosgraph_msgs/msg/Clock", RECORDER_CLOCK_QOS),
    RecordedTopic("/diagnostics", DiagnosticArray, "diagnostic_msgs/msg/DiagnosticArray",
                  RECORDER_QOS),
    RecordedTopic("/parameter_events", ParameterEvent, "rcl_interfaces/msg/ParameterEvent",
                  PARAMETER_EVENTS_QOS),
)
