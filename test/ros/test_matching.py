"""Writer-side matching (``hexapod_vibration.ros.matching``) on real rclpy nodes.

A watched publisher reports the subscriptions it matched and calls back when the count
changes; the runner's check lists the topics whose publisher is behind the graph; a node's
/diagnostics publishers are found and waited for until acknowledged (at exit).
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Float64MultiArray

from hexapod_vibration.ros.matching import (
    MatchedReaders,
    readers_key,
    topic_publishers,
    unmatched_topics,
    wait_for_acks,
)
from hexapod_vibration.ros.qos import DIAGNOSTICS_QOS, LOOP_PUBLISHER_QOS, LOOP_QOS

HANG_GUARD_S = 30.0


def test_a_watched_publisher_reports_its_matched_subscriptions_and_calls_back(ros_context):
    talker = ros_context.create_node("matching_talker")
    listener = ros_context.create_node("matching_listener")
    changes: list[dict[str, int]] = []
    readers = MatchedReaders(lambda: changes.append(readers.values()))
    readers.publisher(talker, Float64MultiArray, "/match/loop", LOOP_PUBLISHER_QOS)
    assert readers.values() == {"/match/loop readers": 0}
    sub = listener.create_subscription(Float64MultiArray, "/match/loop", lambda _m: None,
                                       LOOP_QOS)
    assert ros_context.wait_for(lambda: changes, HANG_GUARD_S), "no matched event"
    assert changes[-1] == {"/match/loop readers": 1}
    listener.destroy_subscription(sub)
    assert ros_context.wait_for(lambda: readers.values()["/match/loop readers"] == 0,
                                  HANG_GUARD_S)
    assert ros_context.wait_for(lambda: changes[-1] == {"/match/loop readers": 0},
                                  HANG_GUARD_S), changes


def test_a_topic_is_unmatched_until_its_publisher_matched_every_subscriber_the_graph_shows():
    graph = {"/a": 2, "/b": 1, "/c": 1}
    driver = {readers_key("/a"): "1", "held": "true"}
    notch = {readers_key("/b"): "1"}
    assert unmatched_topics([driver, notch], ["/a", "/b", "/c"], graph.get) == ["/a", "/c"]
    driver[readers_key("/a")] = "2"
    assert unmatched_topics([driver, notch], ["/a", "/b"], graph.get) == []
    graph["/b"] = 3                          # a subscriber the publisher has not matched yet
    assert unmatched_topics([driver, notch], ["/a", "/b"], graph.get) == ["/b"]


def test_the_nodes_diagnostics_publishers_are_found_and_acknowledged_before_exit(ros_context):
    """What node_runner waits for at exit: every /diagnostics reader acknowledged."""
    talker = ros_context.create_node("flush_talker")
    listener = ros_context.create_node("flush_listener")
    status = talker.create_publisher(DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS)
    talker.create_publisher(Float64MultiArray, "/match/other", LOOP_PUBLISHER_QOS)
    assert topic_publishers([talker, listener], "/diagnostics") == [status]
    listener.create_subscription(DiagnosticArray, "/diagnostics", lambda _m: None,
                                 DIAGNOSTICS_QOS)
    assert ros_context.wait_for(lambda: status.get_subscription_count() >= 1, HANG_GUARD_S)
    for _ in range(20):
        status.publish(DiagnosticArray())
    assert wait_for_acks([status], HANG_GUARD_S) == []
