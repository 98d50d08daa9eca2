"""LoopSpinner (the ``waitset`` executor choice) and StrutArrayPublisher, on real rclpy nodes.

Two nodes in the test process on the test's own domain: a publisher node and a node with a
loop subscription, a non-loop subscription and a parameter. Fast DDS delivers between
nodes of one process without the network, as it does inside ``pph_graph``.
"""

from __future__ import annotations

import numpy as np
import pytest
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray, String

from hexapod_vibration.core.loop.idle_work import IdleWork
from hexapod_vibration.ros.executors import LoopSpinner
from hexapod_vibration.ros.messages import (
    StrutArrayPublisher,
    make_strut_array,
    receive_strut_array,
)
from hexapod_vibration.ros.qos import LOOP_PUBLISHER_QOS, LOOP_QOS

HANG_GUARD_S = 30.0


class Graph:
    """A publisher node and a listener node with a loop and a non-loop subscription."""

    def __init__(self, ros_context):
        self.ctx = ros_context
        self.talker = ros_context.create_node("spinner_talker")
        self.listener = ros_context.create_node("spinner_listener")
        self.listener.declare_parameter("gain", 1.0)
        self.loop_msgs: list[tuple[np.ndarray, int]] = []
        self.other_msgs: list[str] = []
        self.kinds: set[type] = set()
        self.loop_sub = self.listener.create_subscription(
            Float64MultiArray, "/spin/loop", self._on_loop, LOOP_QOS)
        self.listener.create_subscription(String, "/spin/other",
                                          lambda m: self.other_msgs.append(m.data), 10)
        self.loop_pub = StrutArrayPublisher(self.talker.create_publisher(
            Float64MultiArray, "/spin/loop", LOOP_PUBLISHER_QOS))
        self.other_pub = self.talker.create_publisher(String, "/spin/other", 10)

    def _on_loop(self, msg: Float64MultiArray | bytes) -> None:
        # The fast path hands over the serialized message, the executor a Python one.
        self.kinds.add(type(msg))
        values, index = receive_strut_array(msg, self.listener.get_logger(), "/spin/loop")
        self.loop_msgs.append((values.copy(), index))

    def spinner(self, fast: bool = True, service_period_s: float = 0.01,
                idle_work: IdleWork | None = None) -> LoopSpinner:
        return LoopSpinner(self.ctx.executor, [self.loop_sub], fast, service_period_s,
                           idle_work=[] if idle_work is None else [idle_work])

    def spin_until(self, spinner: LoopSpinner, predicate, step=None) -> bool:
        return self.ctx.wait_for(predicate, HANG_GUARD_S, step,
                                 spin=lambda: spinner.spin_once(0.02))

    def connect(self, spinner: LoopSpinner) -> None:
        """Publish index 0 until the listener has it (discovery), then forget it."""
        assert self.spin_until(spinner, lambda: self.loop_msgs,
                               step=lambda: self.loop_pub.publish(np.zeros(6), 0))
        self.loop_msgs.clear()
        self.kinds.clear()


@pytest.mark.parametrize("fast", [True, False])
def test_loop_messages_arrive_in_order_with_their_index(ros_context, fast):
    graph = Graph(ros_context)
    spinner = graph.spinner(fast)
    graph.connect(spinner)
    sent = {n: np.arange(6.0) * n + 0.5 for n in range(1, 9)}
    for n, values in sent.items():        # 8 queued (LOOP_QOS keeps 10), taken in one go
        graph.loop_pub.publish(values, n)
    assert graph.spin_until(spinner, lambda: len(graph.loop_msgs) >= len(sent))
    assert [index for _, index in graph.loop_msgs] == list(sent)
    for (values, index) in graph.loop_msgs:
        np.testing.assert_array_equal(values, sent[index])
    # The fast path takes serialized messages (its executor service may take one too).
    assert (bytes in graph.kinds) if fast else graph.kinds == {Float64MultiArray}


def test_fast_spinner_serves_other_callbacks_and_parameter_services(ros_context):
    graph = Graph(ros_context)
    spinner = graph.spinner(fast=True, service_period_s=0.0)
    graph.connect(spinner)
    graph.other_pub.publish(String(data="hello"))
    assert graph.spin_until(spinner, lambda: graph.other_msgs == ["hello"])

    # The parameter service (what `ros2 param set` calls) of the listener node.
    client = graph.talker.create_client(SetParameters, "/spinner_listener/set_parameters")
    assert graph.spin_until(spinner, client.service_is_ready)
    request = SetParameters.Request(parameters=[Parameter("gain", value=2.5).to_parameter_msg()])
    future = client.call_async(request)
    assert graph.spin_until(spinner, future.done)
    assert future.result().results[0].successful
    assert graph.listener.get_parameter("gain").value == 2.5


def test_fast_spinner_keeps_loop_messages_taken_by_the_executor(ros_context):
    """The executor's service spin may take a loop message: its callback runs all the same."""
    graph = Graph(ros_context)
    spinner = graph.spinner(fast=True, service_period_s=0.0)   # service on every call
    graph.connect(spinner)
    for n in range(1, 201):
        graph.loop_pub.publish(np.full(6, float(n)), n)
        assert graph.spin_until(spinner, lambda n=n: graph.loop_msgs
                                and graph.loop_msgs[-1][1] == n)
    assert [index for _, index in graph.loop_msgs] == list(range(1, 201))


def test_strut_array_publisher_sends_what_make_strut_array_builds(ros_context):
    graph = Graph(ros_context)
    raw_msgs: list[bytes] = []
    graph.listener.create_subscription(Float64MultiArray, "/spin/loop", raw_msgs.append,
                                       LOOP_QOS, raw=True)
    spinner = graph.spinner(fast=False)
    values = np.array([1.0, -2.0, 3.5, 1e-9, -7.25, 123456.0])
    expected = make_strut_array(values, 987654)

    def received() -> bool:
        return any(deserialize_message(raw, Float64MultiArray) == expected for raw in raw_msgs)

    # Publish until the raw subscription is connected and has it (discovery).
    assert graph.spin_until(spinner, received, step=lambda: graph.loop_pub.publish(values, 987654))


@pytest.mark.parametrize("values, index", [(np.zeros(5), 1), (np.zeros(7), 1),
                                           (np.zeros(6), -1)])
def test_strut_array_publisher_rejects_bad_input_and_sends_nothing(ros_context, values, index):
    graph = Graph(ros_context)
    spinner = graph.spinner(fast=True)
    graph.connect(spinner)
    with pytest.raises(ValueError):
        graph.loop_pub.publish(values, index)
    graph.loop_pub.publish(np.ones(6), 5)          # the next good message is intact
    assert graph.spin_until(spinner, lambda: graph.loop_msgs)
    assert len(graph.loop_msgs) == 1
    np.testing.assert_array_equal(graph.loop_msgs[0][0], np.ones(6))
    assert graph.loop_msgs[0][1] == 5


@pytest.mark.parametrize("answered", [1, 2, 3])
def test_a_latest_only_subscription_gets_the_newest_queued_samples(ros_context, answered):
    """The newest ``answered`` of those queued (command delay + 1), oldest first."""
    graph = Graph(ros_context)
    spinner = LoopSpinner(ros_context.executor, [graph.loop_sub], True, 10.0,
                          latest_only=[graph.loop_sub], answered=answered)
    graph.connect(spinner)
    for n in range(1, 6):                   # queued while the listener is not served
        graph.loop_pub.publish(np.full(6, float(n)), n)
    assert graph.spin_until(spinner, lambda: graph.loop_msgs and graph.loop_msgs[-1][1] == 5)
    indices = [index for _, index in graph.loop_msgs]
    assert indices == list(range(6 - answered, 6)), indices
    np.testing.assert_array_equal(graph.loop_msgs[-1][0], np.full(6, 5.0))


def test_the_samples_a_latest_only_subscription_skips_go_to_its_skipped_callback(ros_context):
    graph = Graph(ros_context)
    skipped: list[int] = []
    spinner = LoopSpinner(
        ros_context.executor, [graph.loop_sub], True, 10.0, latest_only=[graph.loop_sub],
        answered=2, skipped={graph.loop_sub: lambda raw: skipped.append(
            receive_strut_array(raw, graph.listener.get_logger(), "/spin/loop")[1])})
    graph.connect(spinner)
    skipped.clear()
    for n in range(1, 6):                   # queued while the listener is not served
        graph.loop_pub.publish(np.full(6, float(n)), n)
    assert graph.spin_until(spinner, lambda: graph.loop_msgs and graph.loop_msgs[-1][1] == 5)
    assert [index for _, index in graph.loop_msgs] == [4, 5]
    assert skipped == [1, 2, 3]               # oldest first, before the newest


def test_deferred_work_waits_until_the_loop_is_idle(ros_context):
    """Not while its owner expects a message; then when a wait finds nothing, messages first."""
    graph = Graph(ros_context)
    work = IdleWork(overdue_s=3600.0)
    spinner = graph.spinner(fast=True, service_period_s=3600.0, idle_work=work)
    graph.connect(spinner)
    def has_sample_1() -> bool:
        return any(index == 1 for _, index in graph.loop_msgs)

    seen: list[bool] = []
    work.defer(lambda: seen.append(has_sample_1()))
    graph.loop_pub.publish(np.full(6, 1.0), 1)
    assert graph.ctx.wait_for(has_sample_1, HANG_GUARD_S,
                              spin=lambda: spinner.spin_once(0.02, idle=False))
    asked: list[bool] = []
    for _ in range(3):                                 # the owner still expects one
        spinner.spin_once(0.0, idle=lambda: asked.append(False) or False)
    assert seen == [] and work.pending and asked == [False] * 3
    spinner.spin_once(0.02, idle=True)                 # nothing queued: the loop is idle
    assert seen == [True] and not work.pending


@pytest.mark.parametrize("fast", [True, False])
def test_overdue_work_runs_whatever_the_loop_does(ros_context, fast):
    graph = Graph(ros_context)
    work = IdleWork(overdue_s=0.0)
    spinner = graph.spinner(fast=fast, service_period_s=3600.0, idle_work=work)
    ran: list[int] = []
    work.defer(lambda: ran.append(1))
    spinner.spin_once(0.0, idle=False)
    assert ran == [1] and not work.pending


def test_the_slow_path_runs_deferred_work_after_its_callbacks_when_idle(ros_context):
    graph = Graph(ros_context)
    work = IdleWork(overdue_s=3600.0)
    spinner = graph.spinner(fast=False, idle_work=work)
    ran: list[int] = []
    work.defer(lambda: ran.append(1))
    spinner.spin_once(0.0, idle=False)
    assert ran == [] and work.pending
    spinner.spin_once(0.0)
    assert ran == [1]


def test_serving_the_loop_alone_runs_deferred_work_when_no_message_came(ros_context):
    """A callback that waits (the notch's setting change) serves the loop and the forecasts."""
    graph = Graph(ros_context)
    work = IdleWork(overdue_s=3600.0)
    spinner = graph.spinner(fast=True, service_period_s=3600.0, idle_work=work)
    ran: list[int] = []
    work.defer(lambda: ran.append(1))
    spinner.serve_loop(0.0)
    assert ran == [1] and not work.pending
