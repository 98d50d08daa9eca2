"""``run_node``: the ``main()`` of every node executable, from rclpy.init to the exit code.

1. The command line is checked first (``cli.node_command_line``: ``--help``, stray
   arguments, ``--params-file``), and SIGINT/SIGTERM raise ``cli.StopSignal`` from then on
   (rclpy's own signal handlers are not installed: they shut the context down from another
   thread, in the middle of whatever the node is doing, which is what made Ctrl-C print
   ``RCLError: context is not valid`` tracebacks). The package's Fast DDS profile is then
   put in the environment before ``rclpy.init`` (:mod:`hexapod_vibration.ros.fastdds_profile`:
   a short heartbeat, so that the exit's acknowledgements below come within ~0.1 s).
2. The node(s) are built (a signal meanwhile is raised once each is whole, so that it is
   destroyed like a running one); a bad parameter or file ends the process with exit
   code 2 and the reason in one line, before the loop starts. The first node's
   ``realtime_priority`` and ``cpu_affinity`` (:mod:`hexapod_vibration.ros.realtime`) then
   apply to the whole process; where the OS refuses them, the process ends the same way.
3. The loop runs until a signal; then every reader of the nodes' ``/diagnostics``
   acknowledges their statuses (at most ``FLUSH_S``), the nodes are destroyed and rclpy is
   shut down in order, and the process ends with ``128 + signal`` (130, 143) at once
   (``cli.exit_now``: no interpreter teardown).
"""

from __future__ import annotations

import gc
import sys
import traceback
from collections.abc import Callable, Sequence

from hexapod_vibration import cli


def run_node(name: str, factory: Callable[[], object],
             loop: Callable | None = None,
             args: list[str] | None = None,
             companions: Sequence[Callable[[], object]] = (),
             nodes: Sequence[str] | None = None) -> None:
    """Init rclpy, build the node(s), run ``loop`` (default: serve them), exit the process.

    The node's 1 kHz subscriptions are those it lists in ``loop_subscriptions`` (those it
    also lists in ``latest_only_subscriptions`` get only the newest ``d + 1`` queued
    messages, ``d`` its ``command_delay_samples``, the older ones going to its
    ``skipped_message_callbacks`` by subscription, if any); its ``executor`` parameter
    chooses how they are served (``ros/executors.py``).
    ``companions`` are more nodes composed into the same process and thread.
    ``nodes``: the node names whose parameters ``--help`` lists (default: ``name``).
    Never returns: exits 0, 2 (bad parameter, file or argument), 128 + signal, or 1 after
    the traceback of an exception in a callback (a bug; the nodes were destroyed first).
    """
    cli.install_stop_handlers()
    args = cli.node_command_line(name, nodes or (name,), args)
    code = cli.EXIT_OK
    try:
        code = _run(name, factory, loop, args, companions)
    except cli.StopSignal as stop:           # during the imports or rclpy.init
        code = stop.exit_code
    except Exception:                        # noqa: BLE001 - a bug: shown, then exit 1
        traceback.print_exc()
        print(f"{name}: internal error: the node stopped (the traceback above)",
              file=sys.stderr, flush=True)
        code = cli.EXIT_FAILED
    cli.exit_now(code)


def _run(name: str, factory, loop, args, companions) -> int:
    import rclpy
    from rclpy.exceptions import InvalidHandle, ParameterException
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions
    from threadpoolctl import threadpool_limits

    from hexapod_vibration.ros.executors import LoopSpinner, make_executor, spin_loop
    from hexapod_vibration.ros.fastdds_profile import use_package_profile
    from hexapod_vibration.ros.rclpy_internals import RCLError
    from hexapod_vibration.ros.realtime import apply_scheduling

    cli.exit_if_stopped()
    use_package_profile()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:
        return cli.fail(name, f"bad ROS arguments: {exc}")
    built: list = []
    code = cli.EXIT_OK
    serving = False          # from here on an exception is a fault of the loop, not a usage error
    try:
        # A signal while a node is built is raised once it is in ``built``: a node that
        # started something (the notch's analysis worker) is then destroyed, which stops it.
        for make in (factory, *companions):
            with cli.deferred():
                built.append(make())
        gc.freeze()        # start-up objects: never scanned again by the collector
        executor_name = built[0].get_parameter("executor").value
        subscriptions = [sub for node in built[1:] + built[:1]
                         for sub in getattr(node, "loop_subscriptions", ())]
        latest = [sub for node in built for sub in getattr(node, "latest_only_subscriptions", ())]
        skipped = {sub: call for node in built
                   for sub, call in getattr(node, "skipped_message_callbacks", {}).items()}
        idle_work = [node.idle_work for node in built if hasattr(node, "idle_work")]
        # A signal in the middle of an rclpy constructor leaves a half-built object whose
        # __del__ prints a traceback: the stop is raised once they are whole.
        with cli.deferred():
            executor = make_executor(executor_name)
            for node in built:
                executor.add_node(node)
            spinner = LoopSpinner(executor, subscriptions, fast=executor_name == "waitset",
                                  latest_only=latest, skipped=skipped,
                                  answered=_command_delay(built[0]) + 1,
                                  idle_work=idle_work)
        for node in built:      # a node whose callbacks may wait serves the loop meanwhile
            if hasattr(node, "serve_loop_with"):
                node.serve_loop_with(spinner)
        _schedule(built[0], apply_scheduling)
        # One BLAS thread: a node's computation (an identification's analysis) must not
        # spread over the cores the loop runs on; under SCHED_FIFO, OpenBLAS's spinning
        # workers stalled the notch's analysis (and the loop) for minutes.
        threadpool_limits(limits=1)
        serving = True
        (loop or spin_loop)(built[0], spinner)
    except cli.StopSignal as stop:
        code = stop.exit_code
    except (ExternalShutdownException, RCLError, InvalidHandle):
        if cli.stop_requested() is None and rclpy.ok():
            raise                                  # a real error, not a shutdown
        code = cli.interrupted_exit_code()
    except (ValueError, FileNotFoundError, ParameterException) as exc:
        if serving:
            raise                    # a bug in a callback: its traceback, exit 1, never exit 2
        print(f"{name}: error: {' '.join(str(exc).split())}", file=sys.stderr, flush=True)
        code = cli.EXIT_USAGE
    finally:
        with cli.deferred():
            if rclpy.ok():          # nothing to wait for when the context is gone
                _flush_diagnostics(name, built)
            for node in reversed(built):
                node.destroy_node()
            rclpy.try_shutdown()
    if code == cli.EXIT_OK and cli.stop_requested() is not None:
        code = cli.interrupted_exit_code()
    return code


def _flush_diagnostics(name: str, built: list) -> None:
    """Before the nodes go: every reader acknowledged their ``/diagnostics`` (<= FLUSH_S).

    A recorder behind a loaded machine can lose one status and get the next ones only
    after the lost one is sent again, at the writer's next heartbeat (3 s): a composed
    graph that then exited took them with it, and a twin run's bag ended with the notch
    still identifying (its status from 2.25 s on never reached the bag), so the report
    left the whole window out.
    """
    from rclpy.exceptions import InvalidHandle

    from hexapod_vibration.ros.matching import FLUSH_S, topic_publishers, wait_for_acks
    from hexapod_vibration.ros.rclpy_internals import RCLError

    try:
        late = wait_for_acks(topic_publishers(built, "/diagnostics"), FLUSH_S)
    except (RCLError, InvalidHandle):
        return
    if late:
        print(f"{name}: exit: /diagnostics not acknowledged by every reader within "
              f"{FLUSH_S:.0f} s: a reader may lack the last statuses", file=sys.stderr,
              flush=True)


def _command_delay(node) -> int:
    """The node's ``command_delay_samples`` (0 if it has none: not a 1 kHz loop node)."""
    if not node.has_parameter("command_delay_samples"):
        return 0
    return int(node.get_parameter("command_delay_samples").value)


def _schedule(node, apply_scheduling) -> None:
    """Apply the node's ``realtime_priority`` and ``cpu_affinity`` to this process (logged).

    Raises:
        ValueError: The OS refuses them (``realtime.SchedulingRefused``).
    """
    names = node.get_parameters(["realtime_priority", "cpu_affinity"]) \
        if node.has_parameter("realtime_priority") else []
    if not names:
        return
    priority, cpus = int(names[0].value), list(names[1].value)
    applied = apply_scheduling(priority, cpus)
    if applied:
        node.get_logger().info(f"scheduling: {applied}")
