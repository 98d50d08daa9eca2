"""Named QoS profiles of the package, and why each is what it is.

Compatibility rules that drive these choices (DDS request/offer): a RELIABLE publisher
serves both RELIABLE and BEST_EFFORT subscriptions, a BEST_EFFORT publisher only
BEST_EFFORT ones; a VOLATILE subscription matches any durability. So publishers here are
RELIABLE and VOLATILE, and subscriptions to topics owned by others (``/clock``) ask for no
more than those owners offer.
"""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_parameter_events,
)

LOOP_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    durability=DurabilityPolicy.VOLATILE,
)
"""Loop topics ``/pph/*`` at 1 kHz (driver <-> controllers).

RELIABLE: in lockstep the driver waits for the command of every sample, so a dropped
message would cost a timeout instead of 1 ms; in realtime mode a lost command is a missed
sample. KEEP_LAST 10: a slow subscriber gets at most 10 ms of backlog, which bounds the
latency and the memory instead of queueing stale commands. VOLATILE: a late joiner must
not receive old samples as if they were current.
"""

COMMAND_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    durability=DurabilityPolicy.VOLATILE,
)
"""The driver's subscriptions to the command topics ``/pph/*_command``.

As LOOP_QOS, but 1000 deep: the driver takes every queued message at each wake-up and
pairs commands with samples by their in-band index (old or repeated ones are refused
cheaply), so depth costs no latency; it only decides how much traffic may arrive while
the driver steps the plant or is descheduled before a legitimate command is pushed out.
Measured: a flood of 20 000 invalid messages (about 18 kHz, from another process) pushed
lockstep commands out of a 10-deep queue (a 2 s timeout per lost command even with the
50 ms re-offer, 1 run in 3). Lockstep re-offers a sample whose commands are missing, so a
command lost all the same costs 50 ms, not the timeout.
"""

OBSERVED_LOOP_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=1000,
    durability=DurabilityPolicy.VOLATILE,
)
"""The notch controller's ``/pph/accel``: as LOOP_QOS, but 1000 deep.

The controller answers only the newest ``command_delay_samples`` + 1 samples queued and
records the older ones into a running identification (a latest-only loop subscription
with a skipped-message callback), so depth costs no latency, and a stall of up to 1 s
costs the identification no sample. At 10 deep every sample beyond the tenth of a stall
was lost: 535 of 41 123 samples in one realtime run, which the identification can only
model (a cubic fill and GMRES).
"""

LOOP_PUBLISHER_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10000,
    durability=DurabilityPolicy.VOLATILE,
)
"""Publishers of the loop topics ``/pph/*``.

Same policies as LOOP_QOS (so they match it), but a writer history of 10 000 samples
(10 s at 1 kHz, 3 s at the composed lockstep loop's ~3.3 kHz): a RELIABLE writer can only
re-send what is still in its history, so a reader that falls behind for a moment (the
recorder during a disk flush or on a loaded machine) would lose samples with a history of
10. Measured: with 10 the recorder lost ~115 of 34 000 samples per topic at load 11; with
1000, none at 1 kHz, but a Python listener lost 285 of 1000 samples behind the composed
lockstep loop at ~3 kHz (none with 10 000, three runs). The depth costs memory (about 2 MB
per topic), not latency. It bounds, not removes, the lag a reader may have: KEEP_LAST never
blocks the loop.
"""

RECORDER_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=5000,
    durability=DurabilityPolicy.VOLATILE,
)
"""Recorder subscriptions to the ``/pph/*``, ``/diagnostics`` topics.

RELIABLE so that the DDS layer retransmits lost packets; KEEP_LAST 5000 (5 s at 1 kHz per
topic) so that samples accumulate in the reader's queue, not get dropped, while the
recorder's Python thread is busy (writer flush, garbage collection). Compatible with
LOOP_QOS publishers (and with ``ros2 topic pub``'s RELIABLE default).
"""

CLOCK_QOS = QoSProfile(
    reliability=ReliabilityPolicy.BEST_EFFORT,
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    durability=DurabilityPolicy.VOLATILE,
)
"""``/clock`` (``rosgraph_msgs/Clock``), as rclpy's TimeSource subscribes to it.

BEST_EFFORT, KEEP_LAST 1, VOLATILE: only the latest time matters (rclcpp's ClockQoS is the
same). A publisher may use this profile or a RELIABLE one: both match these subscribers.
"""

RECORDER_CLOCK_QOS = QoSProfile(
    reliability=ReliabilityPolicy.BEST_EFFORT,
    history=HistoryPolicy.KEEP_LAST,
    depth=5000,
    durability=DurabilityPolicy.VOLATILE,
)
"""Recorder subscription to ``/clock``.

BEST_EFFORT so that it matches every ``/clock`` publisher (a RELIABLE subscription would not
match a BEST_EFFORT one such as rclcpp's ClockQoS); deep like RECORDER_QOS so a busy
recorder keeps every tick it received.
"""

DIAGNOSTICS_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    durability=DurabilityPolicy.VOLATILE,
)
"""``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``), published at about 1 Hz.

The defaults of ``diagnostic_updater`` and of ``ros2 topic echo``: RELIABLE, KEEP_LAST 10,
VOLATILE, so every standard diagnostics tool matches it.
"""

PARAMETER_EVENTS_QOS = qos_profile_parameter_events
"""``/parameter_events`` (``rcl_interfaces/msg/ParameterEvent``): rclpy's own profile
(RELIABLE, KEEP_LAST 1000, VOLATILE), so the recorder keeps every parameter change."""

LATCHED_QOS = QoSProfile(
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""``/pph/notch_sensitivity``: published once per identification, kept for late joiners
(TRANSIENT_LOCAL, the last one). A VOLATILE subscription matches it too but gets only what
is published after it joined; the recorder and the tools subscribe TRANSIENT_LOCAL."""

HELD_QOS = QoSProfile(
    reliability=ReliabilityPolicy.BEST_EFFORT,
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    durability=DurabilityPolicy.VOLATILE,
)
"""``/pph/notch_held`` and ``/pph/stand_ins`` (10 Hz): 100 deep (10 s of reports), so a notch
controller busy for a while (an identification's analysis) still gets every report its DDS
layer received; BEST_EFFORT, each report repeating the rows of the 9 before it
(``core/loop/repeated_reports``): RELIABLE held every report after a lost one until the
writer's next heartbeat repaired it, 1.1-3 s after a controller stopped for 350 ms."""
