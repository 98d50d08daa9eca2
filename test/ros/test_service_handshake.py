"""The parameter client's handshake (``ros.service_handshake``) on real rclpy nodes.

A request sent before the server's endpoints exist is lost (volatile service topics), as
a response is when the server's writer has not matched the client's reader yet: the
handshake must send again until every service answered once, and give up with the names
of the silent services when there is nobody to answer.
"""

from __future__ import annotations

from rclpy.parameter_client import AsyncParameterClient

from hexapod_vibration.ros.service_handshake import shake_hands

HANG_GUARD_S = 60.0


def test_a_server_that_comes_after_the_first_requests_is_asked_again(ros_context):
    client = AsyncParameterClient(ros_context.create_node("handshake_client"), "/late_server")
    spins: list[float] = []

    def spin_once(timeout_s: float) -> None:
        spins.append(timeout_s)
        if len(spins) == 3:              # the first requests went out with no server
            ros_context.create_node("late_server").declare_parameter("gain", 2.0)
        ros_context.executor.spin_once(timeout_sec=timeout_s)

    assert shake_hands(client, spin_once, HANG_GUARD_S, resend_s=0.2) == []
    future = client.get_parameters(["gain"])
    assert ros_context.wait_for(future.done, HANG_GUARD_S)
    assert future.result().values[0].double_value == 2.0


def test_nobody_to_answer_names_every_silent_service(ros_context):
    client = AsyncParameterClient(ros_context.create_node("handshake_client"), "/nobody")
    silent = shake_hands(client, lambda t: ros_context.executor.spin_once(timeout_sec=t),
                         timeout_s=0.3)
    assert silent == ["describe_parameters", "get_parameters", "list_parameters",
                      "set_parameters"]
