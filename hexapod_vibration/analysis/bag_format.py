"""What the package's rosbag2 bags hold: topics and types, typestore, version, storage.

No ROS import (rosbags only). ``custom_data`` keys of ``metadata.yaml`` the recorder and the
experiment write are here too.
"""

from __future__ import annotations

from rosbags.rosbag2 import StoragePlugin
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from hexapod_vibration.contract import (
    DISTURBANCE_FREQUENCIES_TOPIC,
    NOTCH_FREQUENCIES_TOPIC,
    NOTCH_SENSITIVITY_TOPIC,
    REFERENCE_FREQUENCY_TOPIC,
)

STRUT_TOPICS: tuple[str, ...] = (
    "/pph/accel",
    "/pph/eddy",
    "/pph/notch_command",
    "/pph/pointing_command",
    "/pph/actuator_force",
)
"""The contract's ``std_msgs/Float64MultiArray`` topics, six values each."""

ACCEL_TOPIC = "/pph/accel"
STRUT_MSGTYPE = "std_msgs/msg/Float64MultiArray"
CLOCK_TOPIC = "/clock"
CLOCK_MSGTYPE = "rosgraph_msgs/msg/Clock"
PARAMETER_EVENTS_TOPIC = "/parameter_events"
PARAMETER_EVENT_MSGTYPE = "rcl_interfaces/msg/ParameterEvent"
DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_MSGTYPE = "diagnostic_msgs/msg/DiagnosticArray"
WEIGHTS_TOPIC = "/pph/notch_weights"
FREQUENCY_TOPICS: tuple[str, ...] = (
    REFERENCE_FREQUENCY_TOPIC, DISTURBANCE_FREQUENCIES_TOPIC, NOTCH_FREQUENCIES_TOPIC)
"""Frequencies (Hz) per sample: any number of values, ``sample:<n>`` in ``layout.dim[1]``."""
SENSITIVITY_TOPIC = NOTCH_SENSITIVITY_TOPIC

TYPESTORE_NAME = Stores.ROS2_JAZZY
"""rosbags typestore matching ROS 2 Jazzy's message definitions and type hashes."""

BAG_VERSION = 9
"""rosbag2 metadata version written (the one ROS 2 Jazzy writes)."""

STORAGE_PLUGINS = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
"""rosbag2 storage plugins by their ``ros2 bag`` name (the recorder's ``storage``)."""

RECORDING_KEY = "hexapod_vibration.recording"
"""``custom_data`` key of the provisional ``metadata.yaml`` written when a recording starts;
the final one (written when the bag is closed) does not have it."""

RECORDING_OPEN = "open"

RUN_RECORD_KEY = "hexapod_vibration.run"
"""``custom_data`` key holding the experiment's run record (JSON), see
:mod:`hexapod_vibration.analysis.run_record`."""

_TYPESTORE: Typestore | None = None


def typestore() -> Typestore:
    """The shared rosbags typestore for ROS 2 Jazzy (built once)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(TYPESTORE_NAME)
    return _TYPESTORE
