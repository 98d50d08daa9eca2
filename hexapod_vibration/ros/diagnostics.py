"""``/diagnostics`` messages shared by the nodes.

The driver's ``/clock`` bytes are :func:`hexapod_vibration.cdr.clock_cdr`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer

from hexapod_vibration.contract import sample_sim_time
from hexapod_vibration.diagnostics_cdr import OK, WARN, encode_diagnostics_cdr

HARDWARE_ID = "pph_sim"
STATUS_PERIOD_S = 1.0
"""Period (s, wall time) at which every node re-publishes its status on ``/diagnostics``,
as ``diagnostic_updater`` does (1 Hz), whether or not its loop moves."""


def diagnostic_array(name: str, warn: bool, message: str, values: Mapping[str, object],
                     sample: int) -> bytes:
    """One status (OK or WARN) with ``values`` as key/value pairs, stamped at ``sample``.

    The serialized ``diagnostic_msgs/DiagnosticArray`` (``diagnostics_cdr``), published
    as is: a publisher of DiagnosticArray takes the bytes.
    """
    return encode_diagnostics_cdr(WARN if warn else OK, name, message, HARDWARE_ID, values,
                                  *sample_sim_time(sample))


def publish_status_periodically(node: Node, publish: Callable[[], None],
                                period_s: float = STATUS_PERIOD_S) -> Timer:
    """Call ``publish`` every ``period_s`` of wall (steady) time, whatever the sim clock does.

    A status published only as samples arrive stops when the loop stops (a lockstep driver
    holding, a driver restarting): a ``ros2 topic echo /diagnostics`` started then, or a
    subscriber whose match with this publisher completed late (discovery on a loaded
    machine), would never see the node. The steady clock keeps the re-announcement going
    under ``use_sim_time`` too.
    """
    return node.create_timer(period_s, publish, clock=Clock(clock_type=ClockType.STEADY_TIME))
