"""``run_node``: a signal while a node is being built still destroys that node.

The probe is a real rclpy node in its own process (``run_node`` ends the process): its
constructor signals its own process half-way, as Ctrl-C would while a node is starting (the
notch controller's analysis worker is then already running: a node left undestroyed left
the worker's semaphores to multiprocessing's resource tracker, which complained).
"""

from __future__ import annotations

import signal
import sys
import textwrap

import pytest

HANG_GUARD_S = 60.0
PROBE = textwrap.dedent("""
    import os, signal, sys
    from rclpy.node import Node
    from hexapod_vibration.ros.node_runner import run_node

    class Probe(Node):
        def __init__(self):
            super().__init__("probe")
            os.kill(os.getpid(), signal.{signal})   # delivered before the constructor ends
            for _ in range(1000):                   # bytecodes in which it is handled
                pass
            print("built", flush=True)

        def destroy_node(self):
            print("destroyed", flush=True)
            super().destroy_node()

    run_node("probe", Probe, args=[])
""")


def _run_probe(node_processes, script: str) -> tuple[int, str]:
    """Run ``script`` as a node process to its end: (exit code, its output)."""
    process = node_processes.start("probe", command=[sys.executable, "-c", script])
    code = process.wait(HANG_GUARD_S)
    return code, process.output()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_node_signalled_while_built_is_destroyed(node_processes, signum):
    code, output = _run_probe(node_processes, PROBE.format(signal=signal.Signals(signum).name))
    assert code == 128 + signum, output
    assert "built" in output and "destroyed" in output, output
    assert "Traceback" not in output, output


FAULTY = textwrap.dedent("""
    from rclpy.node import Node
    from hexapod_vibration.ros.node_runner import run_node

    class Probe(Node):
        def __init__(self):
            super().__init__("probe")
            self.declare_parameter("executor", "waitset")
            if {at_start}:
                raise ValueError("bad start value")

        def destroy_node(self):
            print("destroyed", flush=True)
            super().destroy_node()

    def serve(node, spinner):
        raise ValueError("a fault in the loop")

    run_node("probe", Probe, serve, args=[])
""")


def test_a_value_error_while_serving_is_a_fault_not_a_usage_error(node_processes):
    """Exit 2 and one line are for refused start-up values; a callback's error is a bug."""
    code, output = _run_probe(node_processes, FAULTY.format(at_start=False))
    assert code == 1, output
    assert "Traceback" in output and "ValueError: a fault in the loop" in output, output
    assert "probe: internal error" in output and "destroyed" in output, output
    assert "probe: error:" not in output, output


def test_a_value_error_while_built_is_one_line_and_exit_2(node_processes):
    code, output = _run_probe(node_processes, FAULTY.format(at_start=True))
    assert code == 2, output
    assert "probe: error: bad start value" in output and "Traceback" not in output, output
