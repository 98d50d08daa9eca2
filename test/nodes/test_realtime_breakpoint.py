"""A realtime driver's breakpoint (``hold_at_time_s``): the clock stops before the sample.

The driver publishes nothing while held (the force of the sample before the breakpoint
included: a realtime driver defers it to the next sample, the hold flushes it) and, moved
on, resumes from the breakpoint without a gap. Judged on the samples received and the
driver's announcements only, never on timing.
"""

from __future__ import annotations

from node_graph import Diagnostics, ParameterClient, StrutTopic, wait_until

from hexapod_vibration.contract import DRIVER_STATUS

FIRST_HOLD = 300
SECOND_HOLD = 700


def test_a_realtime_driver_stops_at_a_breakpoint_and_resumes_there(ros_context,
                                                                   node_processes):
    node = ros_context.create_node("breakpoint_listener")
    accel = StrutTopic(node, "/pph/accel")
    force = StrutTopic(node, "/pph/actuator_force")
    diagnostics = Diagnostics(node)
    driver = node_processes.start("pph_driver", "--ros-args", "-p", "clock_mode:=realtime",
                                  "-p", "lockstep_controllers:=[]",
                                  "-p", "hold_at_time_s:=0.0")

    def held_at(sample: int) -> bool:
        return (diagnostics.value(DRIVER_STATUS, "held") == "true"
                and diagnostics.int_value(DRIVER_STATUS, "sample") == sample)

    def readers(topic: str) -> int:
        return int(diagnostics.value(DRIVER_STATUS, f"{topic} readers", "0"))

    # The start breakpoint until the driver's publishers matched this listener.
    assert wait_until(ros_context, lambda: not driver.running() or (
        held_at(0) and readers("/pph/accel") >= 1 and readers("/pph/actuator_force") >= 1)
    ), driver.output()
    params = ParameterClient(ros_context, node, "pph_driver")
    assert params.set("hold_at_time_s", FIRST_HOLD / 1000).successful
    assert wait_until(ros_context, lambda: not driver.running() or (
        held_at(FIRST_HOLD) and accel.last_index == FIRST_HOLD - 1
        and force.last_index == FIRST_HOLD - 1)), (accel.last_index, force.last_index,
                                                   diagnostics.values(DRIVER_STATUS))
    # Held: announced again (every 0.5 s), nothing published in between.
    announcements = len(diagnostics.history_values(DRIVER_STATUS))
    assert wait_until(ros_context, lambda: len(diagnostics.history_values(DRIVER_STATUS))
                      >= announcements + 2)
    assert held_at(FIRST_HOLD)
    assert (accel.last_index, force.last_index) == (FIRST_HOLD - 1, FIRST_HOLD - 1)
    # Moved on: the loop resumes at the breakpoint's sample, no sample skipped.
    assert params.set("hold_at_time_s", SECOND_HOLD / 1000).successful
    assert wait_until(ros_context, lambda: not driver.running() or (
        held_at(SECOND_HOLD) and accel.last_index == SECOND_HOLD - 1
        and force.last_index == SECOND_HOLD - 1)), driver.output()
    for topic in (accel, force):
        assert all(n in topic.by_index for n in range(FIRST_HOLD, SECOND_HOLD)), topic.topic
    assert driver.running(), driver.output()
