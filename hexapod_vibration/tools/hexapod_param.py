"""``hexapod_param``: list, get, set, dump and load a running node's parameters.

For the virtualenv set-up (rclpy from PyPI wheels), which has no ``ros2`` command: this
talks to a node's parameter services (``/NODE/list_parameters``, ``get_parameters``,
``describe_parameters``, ``set_parameters``) as ``ros2 param`` does, so a run-time change
goes through exactly the checks a ``ros2 param set`` meets. A value is written as for
``ros2 param set`` (YAML: ``0.002``, ``true``, ``"[40.0, 80.0]"``) and then fitted to the
parameter's declared type: an integer or ``1e-3`` given for a double, ``[]`` or ``[1, 2]``
for a double array, any word for a string.

Exit codes: 0 done; 1 the node refused (its reason on stderr, one line) or has no such
parameter; 2 a bad command line; 3 the node did not answer (not running, or on another
``ROS_DOMAIN_ID``). Standard library only at import time: rclpy is imported once the
command line is known to be good.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from collections.abc import Sequence
from typing import Any

from hexapod_vibration import cli
from hexapod_vibration.params_files import node_parameters

EXIT_REFUSED = cli.EXIT_FAILED
EXIT_UNREACHABLE = 3
DEFAULT_TIMEOUT_S = 5.0
"""How long to wait for the node's parameter services (s)."""
ANSWER_TIMEOUT_S = 60.0
"""Shortest wait (s) for a found node's answer (``--timeout`` if longer). A node checks a
set of changes before it answers (the notch controller computes the stability bound of new
tones on its identified G(f): 0.2-0.5 s on the project machine, seconds when it is loaded);
a node that never answers still ends the call."""
_NODE_NAME = re.compile(r"/?[A-Za-z_]\w*(/[A-Za-z_]\w*)*")

EPILOG = """examples:
  hexapod_param list /notch_controller
  hexapod_param get /notch_controller mu tone_frequencies_hz
  hexapod_param set /notch_controller mu 0.005
  hexapod_param set /notch_controller tone_frequencies_hz "[40.0, 80.0, 120.0]"
  hexapod_param dump /pph_driver > pph_driver.yaml
  hexapod_param load /pph_driver pph_driver.yaml

exit codes: 0 done, 1 refused by the node (its reason is printed) or no such parameter,
2 bad command line, 3 the node did not answer."""


def node_name(text: str) -> str:
    """An argparse type: a node name, ``/notch_controller`` or ``notch_controller``."""
    if not _NODE_NAME.fullmatch(text):
        raise argparse.ArgumentTypeError(f"not a ROS node name: {text!r}")
    return text if text.startswith("/") else f"/{text}"


def build_parser() -> argparse.ArgumentParser:
    """Command line of ``hexapod_param`` (checked before rclpy is imported)."""
    parser = cli.ArgumentParser(
        prog="hexapod_param", description=__doc__.split("\n")[0].strip("`").split(": ", 1)[1],
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timeout", type=cli.number(0.0, 600.0, "s", low_open=True),
                        default=DEFAULT_TIMEOUT_S, metavar="S",
                        help="wait this long for the node (default "
                             f"{DEFAULT_TIMEOUT_S:g} s); an answer, at least "
                             f"{ANSWER_TIMEOUT_S:g} s")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, text in (("list", "the node's parameter names"),
                       ("dump", "every parameter as a ROS params file (YAML) on stdout")):
        commands.add_parser(name, help=text, description=text).add_argument(
            "node", type=node_name, metavar="NODE", help="node name, e.g. /notch_controller")
    get = commands.add_parser("get", help="parameter values", description="parameter values")
    get.add_argument("node", type=node_name, metavar="NODE")
    get.add_argument("names", nargs="+", metavar="NAME")
    put = commands.add_parser("set", help="set one parameter (as ros2 param set)",
                              description="set one parameter (as ros2 param set)")
    put.add_argument("node", type=node_name, metavar="NODE")
    put.add_argument("name", metavar="NAME")
    put.add_argument("value", metavar="VALUE", help='YAML, e.g. 0.002, true, "[40.0, 80.0]"')
    load = commands.add_parser("load", help="set every parameter of a params file (read-only "
                               "ones are skipped)", description="set every parameter of a "
                               "params file for this node (read-only ones are skipped)")
    load.add_argument("node", type=node_name, metavar="NODE")
    load.add_argument("file", type=cli.existing_file, metavar="FILE")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code (see the module docstring)."""
    args = build_parser().parse_args(argv)
    file_values = node_parameters(args.file, args.node) if args.command == "load" else None
    if isinstance(file_values, str):
        return cli.fail("hexapod_param", file_values)
    from hexapod_vibration.tools.parameter_services import (
        ParameterServices,
        Refused,
        Unreachable,
    )

    try:
        with ParameterServices(args.node, args.timeout,
                               max(args.timeout, ANSWER_TIMEOUT_S)) as node:
            return _run(node, args, file_values)
    except Refused as exc:
        print(f"hexapod_param: error: {exc}", file=sys.stderr, flush=True)
        return EXIT_REFUSED
    except Unreachable as exc:
        domain = os.environ.get("ROS_DOMAIN_ID", "0")
        print(f"hexapod_param: error: {exc} (is it running, on ROS_DOMAIN_ID={domain}?)",
              file=sys.stderr, flush=True)
        return EXIT_UNREACHABLE


def _run(node, args: argparse.Namespace, file_values: dict[str, Any] | None) -> int:
    """Carry out one command on a connected node."""
    if args.command == "list":
        print("\n".join(sorted(node.names())))
    elif args.command == "get":
        for name, value in zip(args.names, node.get(args.names), strict=True):
            print(f"{name}: {value_text(value)}")
    elif args.command == "set":
        sent, now = (value_text(v) for v in node.set(args.name, args.value))
        print(f"{args.node}: {args.name} = {now}"
              + ("" if now == sent else f" (set to {sent}; the node changed it since)"))
    elif args.command == "dump":
        import yaml

        names = sorted(node.names())
        values = dict(zip(names, node.get(names), strict=True))
        print(yaml.dump({args.node: {"ros__parameters": values}}, default_flow_style=False),
              end="")
    else:
        skipped = node.load(file_values)
        print(f"{args.node}: set {len(file_values) - len(skipped)} parameter(s)"
              + (f"; skipped read-only: {', '.join(skipped)}" if skipped else ""))
    return cli.EXIT_OK


def value_text(value: Any) -> str:
    """A parameter value as ``hexapod_param set`` takes it back (JSON, which YAML reads)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return json.dumps(value)
