"""The DDS transport of a realtime graph's processes: UDP, not Fast DDS's shared memory.

Measured (2026-12-05, 2-core machine, Fast DDS 2.14 of the Jazzy wheels, default discovery
range): a realtime graph (driver, notch and pointing controllers as processes, SCHED_FIFO
50, a tone being cancelled) while a plain rclpy node joined the domain 20 times. With the
default transports (shared memory + UDP) 9 of the 20 joins stalled the loop: 343-355
samples missing at the controllers each, the driver's longest period 333.5 ms. A stack
dump in a stall (gdb): the driver's discovery thread, answering the newcomer, opens its
shared-memory port and waits in the port's health check
(``SharedMemGlobal::open_port_internal`` -> ``open_or_create_and_lock_named_mutex``)
holding the participant's send lock, and the loop's publish waits for that lock
(``RTPSWriter::send_nts``): Fast DDS issue 6535 (a fresh port's health check waits ~333 ms
with the default timeout and blocks unrelated publishers). With the built-in transports
limited to UDPv4 (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): 0 of 20 joins stalled (40 samples
at most), for 5-11 % more CPU per sample (driver 671 against 635 us, notch 347 against 312,
pointing 320 against 304). A `ros2 param set` or `ros2 topic echo` during a realtime run is
such a join: one stall zeroed the pointing force (no command nor forecast for 333 ms) and
the transient made the notch's guard fade control out.

Under ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (or ``ROS_LOCALHOST_ONLY=1``)
rmw_fastrtps replaces the built-in transports with its own shared memory + UDP ones, so
the variable has no effect there: the one-line note says so.
"""

from __future__ import annotations

from collections.abc import Mapping

TRANSPORT_VARIABLE = "FASTDDS_BUILTIN_TRANSPORTS"
REALTIME_TRANSPORTS = "UDPv4"
"""Fast DDS's built-in transports for a realtime graph (see the module)."""
PROFILES_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
"""Fast DDS's profiles-file variables (Jazzy's Fast DDS 2 reads the first)."""
USER_CHOICES = (TRANSPORT_VARIABLE, *PROFILES_VARIABLES)
"""Variables by which a user chose the transports already: left as they are."""


def uses_fastrtps(env: Mapping[str, str]) -> bool:
    """True when the nodes' RMW is rmw_fastrtps (``RMW_IMPLEMENTATION``; Jazzy's default)."""
    return env.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp").startswith("rmw_fastrtps")


def localhost_only(env: Mapping[str, str]) -> bool:
    """True when rmw_fastrtps limits discovery to this host (it then sets the transports)."""
    return (env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() == "LOCALHOST"
            or env.get("ROS_LOCALHOST_ONLY", "").strip() == "1")


def realtime_transport_variables(env: Mapping[str, str]) -> tuple[dict[str, str], str]:
    """The variables to add to ``env`` for a realtime graph, and a one-line note ('' if none).

    ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` unless another RMW is chosen, the user chose the
    transports (:data:`USER_CHOICES`), or discovery is localhost-only (then none, and the
    note says why the stalls may come).
    """
    if not uses_fastrtps(env):
        return {}, ""
    if any(env.get(name) for name in USER_CHOICES):
        return {}, ""
    if localhost_only(env):
        return {}, ("localhost-only discovery: rmw_fastrtps adds Fast DDS's shared-memory "
                    "transport, and a ROS process joining the domain may stall the loop "
                    "~333 ms (docs/performance.md)")
    return {TRANSPORT_VARIABLE: REALTIME_TRANSPORTS}, ""


def realtime_transport_env(env: Mapping[str, str]) -> tuple[dict[str, str], str]:
    """A copy of ``env`` with :func:`realtime_transport_variables`, and the one-line note."""
    added, note = realtime_transport_variables(env)
    return {**env, **added}, note
