"""Executor choice for the 1 kHz nodes (a parameter of each node, for the benchmarks).

``single_threaded`` is rclpy's SingleThreadedExecutor (the default: predictable, one
thread); ``events`` is rclpy's experimental EventsExecutor (Jazzy), which skips the wait-set
rebuild of every spin and is cheaper per callback.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

EXECUTORS = ("single_threaded", "events")


def make_executor(name: str) -> Executor:
    """Create the executor called ``name`` (one of :data:`EXECUTORS`)."""
    if name == "single_threaded":
        return SingleThreadedExecutor()
    if name == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    raise ValueError(f"executor must be one of {EXECUTORS}, got {name!r}")


def run_node(name: str, factory: Callable[[], Node],
             loop: Callable[[Node, Executor], None] | None = None,
             args: list[str] | None = None) -> None:
    """Init rclpy, build the node, spin it (or run ``loop``), shut down cleanly.

    Ctrl-C / SIGTERM end the process quietly with the bag-friendly clean shutdown; a bad
    parameter (ValueError) or a missing file ends it with exit code 2 and the reason.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = factory()
        executor = make_executor(node.get_parameter("executor").value)
        executor.add_node(node)
        if loop is None:
            executor.spin()
        else:
            loop(node, executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if rclpy.ok():        # a real error, not the context closed by a signal
            raise
    except (ValueError, FileNotFoundError, ParameterException) as exc:
        print(f"{name}: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
