"""Writer-side matching: how many subscriptions each loop publisher has matched.

Discovery is asymmetric. A subscription can report its publisher matched (the reader's
side) while that publisher has not matched the subscription yet, and a VOLATILE publisher
drops what it sends meanwhile: a recorder that has reported every publisher matched on its
side can still miss the first samples of every loop topic (a lockstep bag began at sample
290, and the run waited for samples that never came).

So each node reports on ``/diagnostics`` how many subscriptions its loop publishers have
matched (``<topic> readers``, :func:`readers_key`), publishes its status again as soon as
one of those counts changes (:class:`MatchedReaders`), and the experiment runner starts a
lockstep loop only once every loop publisher has matched every subscription the graph shows
on its topic (:func:`unmatched_topics`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.publisher import Publisher

READERS_SUFFIX = " readers"
FLUSH_S = 5.0
"""Longest wait (s, wall) at exit for the readers to acknowledge every sample published.

Longer than Fast DDS's heartbeat period (3 s by default): a sample lost on its way to a
starved reader (a recorder on a loaded machine) is only sent again after the writer's next
heartbeat, so a shorter wait (it was 2 s) let a realtime run's bag lose its last 185 ms."""


def readers_key(topic: str) -> str:
    """The ``/diagnostics`` key of the subscriptions ``topic``'s publisher has matched."""
    return f"{topic}{READERS_SUFFIX}"


class MatchedReaders:
    """The matched-subscription counts of a node's loop publishers, for its status.

    Args:
        on_change: called (from the executor) whenever a watched publisher's match count
            changes; a node passes its ``publish_diagnostics``.
    """

    def __init__(self, on_change: Callable[[], None]) -> None:
        """Nothing watched yet."""
        self._on_change = on_change
        self._publishers: dict[str, Publisher] = {}

    def callbacks(self) -> PublisherEventCallbacks:
        """The ``event_callbacks`` to create a watched publisher with."""
        return PublisherEventCallbacks(matched=lambda _info: self._on_change())

    def watch(self, publisher: Publisher) -> Publisher:
        """Report ``publisher``'s matched subscriptions (returned, for chaining)."""
        self._publishers[publisher.topic_name] = publisher
        return publisher

    def publisher(self, node: Node, msg_type: Any, topic: str, qos: Any) -> Publisher:
        """``node.create_publisher(msg_type, topic, qos)``, watched (with :meth:`callbacks`)."""
        return self.watch(node.create_publisher(msg_type, topic, qos,
                                                event_callbacks=self.callbacks()))

    def wait_for_acks(self, timeout_s: float) -> list[str]:
        """Wait (at most ``timeout_s`` in all) until every reader acknowledged what was sent.

        Before a node exits: a RELIABLE writer destroyed with unacknowledged samples drops
        them, and a reader that lags (a recorder on a loaded machine) loses the run's tail.
        Returns the topics still unacknowledged.
        """
        return wait_for_acks(self._publishers.values(), timeout_s)

    def values(self) -> dict[str, int]:
        """``{"<topic> readers": matched subscriptions}`` of every watched publisher."""
        return {readers_key(topic): publisher.get_subscription_count()
                for topic, publisher in self._publishers.items()}


def wait_for_acks(publishers: Iterable[Publisher], timeout_s: float) -> list[str]:
    """Wait (at most ``timeout_s`` in all) until every reader acknowledged what was sent.

    Returns the topics of the publishers still unacknowledged (a RELIABLE writer destroyed
    with unacknowledged samples drops them).
    """
    deadline = time.monotonic() + timeout_s
    return [publisher.topic_name for publisher in publishers
            if not publisher.wait_for_all_acked(
                Duration(seconds=max(0.0, deadline - time.monotonic())))]


def topic_publishers(nodes: Iterable[Node], topic: str) -> list[Publisher]:
    """The publishers the ``nodes`` created on ``topic``."""
    return [pub for node in nodes for pub in node.publishers if pub.topic_name == topic]


def unmatched_topics(statuses: Iterable[Mapping[str, str]], topics: Iterable[str],
                     subscribers: Callable[[str], int]) -> list[str]:
    """Topics whose publisher has not matched every subscription the graph shows.

    Args:
        statuses: the nodes' ``/diagnostics`` values (key -> text).
        topics: the loop topics to check.
        subscribers: the number of subscriptions the graph shows on a topic.

    Returns:
        The topics no status reports yet, or whose reported count is below the graph's.
    """
    statuses = list(statuses)
    out = []
    for topic in topics:
        key = readers_key(topic)
        reported = [int(s[key]) for s in statuses if key in s]
        if not reported or max(reported) < subscribers(topic):
            out.append(topic)
    return out
