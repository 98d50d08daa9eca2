"""An rclpy context of the test process on the test's ROS domain (the ``ros_context`` fixture).

Imported by ``test/conftest.py`` only when a test asks for ``ros_context``, so that the
tests that need no ROS do not import rclpy.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


class RosTestContext:
    """An rclpy context of the test process on the test's domain, with an executor."""

    def __init__(self, domain_id: int):
        """Initialise rclpy on ``domain_id`` without touching the process's signal handlers."""
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(
            context=self.context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []

    def create_node(self, name: str, **kwargs) -> Node:
        """A node in this context, spun by :meth:`wait_for`."""
        node = rclpy.create_node(name, context=self.context, **kwargs)
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def wait_for(
        self,
        predicate: Callable[[], bool],
        timeout_s: float,
        step: Callable[[], None] | None = None,
        spin: Callable[[], None] | None = None,
    ) -> bool:
        """Spin until ``predicate()`` holds; False after ``timeout_s`` (a hang guard only).

        Args:
            predicate: Condition to wait for.
            timeout_s: Give up after this long (s); choose it generously.
            step: Called before each spin (e.g. to publish something repeatedly).
            spin: One spin (default: the context's executor, up to 50 ms).
        """
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            if step is not None:
                step()
            if spin is None:
                self.executor.spin_once(timeout_sec=0.05)
            else:
                spin()
        return True

    def shutdown(self) -> None:
        """Destroy the nodes and shut the context down."""
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.context)
