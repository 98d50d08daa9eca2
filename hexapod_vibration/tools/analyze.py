"""``analyze BAG [--tones F ...] --out DIR``: the paper's table and figures from any bag.

Works on bags of this package's experiment runner and on bags recorded with
``ros2 bag record`` (MCAP or sqlite3) that hold ``/pph/accel`` (and optionally the other
contract topics, ``/diagnostics`` and ``/parameter_events``). Writes ``DIR/report.json``,
``DIR/details.json`` and PNG plots, and prints the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hexapod_vibration.analysis.bag_io import BagError
from hexapod_vibration.analysis.report import (
    Request,
    WindowTooShort,
    analyze_bag,
    format_harmonics,
    format_table,
)
from hexapod_vibration.core.model.config import load_model_config
from hexapod_vibration.paths import config_path


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 < value < 500.0 or value != value:
        raise argparse.ArgumentTypeError(f"must be in (0, 500) Hz, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """Command-line interface of ``analyze``."""
    parser = argparse.ArgumentParser(prog="analyze", description=__doc__.split("\n")[0])
    parser.add_argument("bag", type=Path, help="rosbag2 directory (MCAP or sqlite3)")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--tones", type=_positive_float, nargs="+", metavar="HZ",
                        help="tones to report (default: the notch controller's tones found "
                             "in the bag, else the 3 strongest peaks)")
    parser.add_argument("--control-on", type=float, metavar="S", default=None,
                        help="sim time (s) control went on (default: from the bag)")
    parser.add_argument("--window", type=float, default=None, metavar="S",
                        help="spectrum window length (s; default: the run's, else 10 s)")
    parser.add_argument("--harmonics-of", type=float, default=None, metavar="HZ",
                        help="also report harmonic distortion of this fundamental")
    parser.add_argument("--scenario", default=None,
                        help="name written into report.json (default: the run's, else the "
                             "bag directory's name)")
    parser.add_argument("--model", type=Path, default=None,
                        help="physical model YAML for the Jacobian (default: packaged)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (2 on bad input, with the reason on stderr)."""
    args = build_parser().parse_args(argv)
    if args.window is not None and args.window <= 0.0:
        print("analyze: --window must be > 0 s", file=sys.stderr)
        return 2
    try:
        model = load_model_config(args.model or config_path("pph_model.yaml"))
        request = Request(args.tones, args.scenario, args.window, args.harmonics_of)
        result = analyze_bag(args.bag, args.out, model, request, args.control_on,
                             plots=not args.no_plots)
    except (BagError, WindowTooShort, ValueError, FileNotFoundError) as exc:
        print(f"analyze: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(format_table(result.report, result.paper_reduction_db))
    if result.harmonics is not None:
        print(format_harmonics(result.harmonics, result.report["scenario"]))
    for note in result.details["notes"]:
        print(f"note: {note}")
    print(f"wrote {args.out / 'report.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
