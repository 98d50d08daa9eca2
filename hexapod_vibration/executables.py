"""The console scripts of the package (``setup.py``), each cheap until its arguments are good.

Every entry point here imports nothing heavy before it has (1) installed the stop
handlers (a SIGINT or SIGTERM during the seconds of start-up imports exits 130/143
quietly) and (2) checked the command line: ``--help`` prints usage and exits 0, a bad
argument exits 2 with one line (``hexapod_vibration.cli``). Only then is the real module
imported and run. ``test/test_executables.py`` checks this for every console script in
``setup.py``, so a new executable should be added here the same way (a node with
:func:`_node`, a tool whose module imports only the standard library at the top).
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence

from hexapod_vibration import cli

LOOP_NODES = ("pph_driver", "notch_controller", "pointing_controller")


def _import_main(module: str):
    """The module's ``main``; a stop signal during the import ends it once it is done.

    The signal is held back while the import runs (``cli.deferred``): raised inside an
    extension module's initialisation it would turn into an ImportError with a traceback
    (seen: numpy's ``PyCapsule_Import could not import module "datetime"``).
    """
    with cli.deferred():
        main = importlib.import_module(module).main
    cli.exit_if_stopped()
    return main


def _node(executable: str, module: str, nodes: Sequence[str], argv: Sequence[str] | None
          ) -> None:
    cli.install_stop_handlers()
    args = cli.node_command_line(executable, nodes, argv)
    try:
        main = _import_main(module)
        main(args)
    except cli.StopSignal as stop:
        cli.exit_now(stop.exit_code)
    cli.exit_now(cli.EXIT_OK)


def _tool(module: str, argv: Sequence[str] | None) -> None:
    cli.install_stop_handlers()
    try:
        main = _import_main(module)
        code = main(None if argv is None else list(argv))
    except cli.StopSignal as stop:
        code = stop.exit_code
    cli.exit_now(int(code or 0))


def pph_driver(argv: Sequence[str] | None = None) -> None:
    """``pph_driver``: the simulated hexapod."""
    _node("pph_driver", "hexapod_vibration.nodes.pph_driver", ("pph_driver",), argv)


def notch_controller(argv: Sequence[str] | None = None) -> None:
    """``notch_controller``: the six Adaptive Notch Cancellers."""
    _node("notch_controller", "hexapod_vibration.nodes.notch_controller",
          ("notch_controller",), argv)


def pointing_controller(argv: Sequence[str] | None = None) -> None:
    """``pointing_controller``: the pointing law."""
    _node("pointing_controller", "hexapod_vibration.nodes.pointing_controller",
          ("pointing_controller",), argv)


def pph_graph(argv: Sequence[str] | None = None) -> None:
    """``pph_graph``: the three loop nodes in one process."""
    _node("pph_graph", "hexapod_vibration.nodes.pph_graph", LOOP_NODES, argv)


def pph_recorder(argv: Sequence[str] | None = None) -> None:
    """``pph_recorder``: the bag recorder."""
    _node("pph_recorder", "hexapod_vibration.nodes.recorder", ("pph_recorder",), argv)


def experiment(argv: Sequence[str] | None = None) -> None:
    """``experiment``: one scenario through the ROS graph."""
    _tool("hexapod_vibration.tools.experiment", argv)


def analyze(argv: Sequence[str] | None = None) -> None:
    """``analyze``: the report of a bag."""
    _tool("hexapod_vibration.tools.analyze", argv)


def soak(argv: Sequence[str] | None = None) -> None:
    """``soak``: hours of lockstep, memory and health sampled."""
    _tool("hexapod_vibration.tools.soak", argv)


def sweep(argv: Sequence[str] | None = None) -> None:
    """``sweep``: a grid of core closed-loop runs on Dask."""
    _tool("hexapod_vibration.tools.sweep", argv)


def hexapod_param(argv: Sequence[str] | None = None) -> None:
    """``hexapod_param``: a running node's parameters, without the ``ros2`` CLI."""
    _tool("hexapod_vibration.tools.hexapod_param", argv)


def hexapod_bench(argv: Sequence[str] | None = None) -> None:
    """``hexapod_bench``: the benchmarks."""
    _tool("hexapod_vibration.bench.cli", argv)
