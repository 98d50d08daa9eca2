"""``analyze BAG [--tones F ...] [--twin TWIN_BAG] --out DIR``: the paper's table and figures.

Works on bags of this package's experiment runner and on bags recorded with
``ros2 bag record`` (MCAP or sqlite3) that hold ``/pph/accel`` (and optionally the other
contract topics, ``/diagnostics`` and ``/parameter_events``). Writes ``DIR/report.json``,
``DIR/details.json`` and PNG plots, and prints the table. ``--twin TWIN_BAG``: the same
run with control never on (``experiment --twin``); the controlled window is compared with
the same samples of the twin (report.json's ``twin`` section, see ``analysis.twin``).
"""

from __future__ import annotations

import argparse
import sys

from hexapod_vibration import cli
from hexapod_vibration.paths import config_path
from hexapod_vibration.tools import outputs

DEFAULT_WINDOW_S = 10.0
"""Same as ``analysis.report.DEFAULT_WINDOW_S`` (tested); here so ``--help`` stays cheap."""
DEFAULT_TWIN_SEGMENT_S = 1.0
"""Same as ``analysis.twin.DEFAULT_SEGMENT_S`` (tested)."""


def build_parser() -> argparse.ArgumentParser:
    """Command-line interface of ``analyze`` (every value checked before any work)."""
    parser = cli.ArgumentParser(prog="analyze", description=__doc__.split("\n")[0])
    parser.add_argument("bag", type=cli.existing_dir, help="rosbag2 directory (MCAP or sqlite3)")
    parser.add_argument("--out", type=cli.output_dir, required=True,
                        help="output directory (its files are replaced only once all are "
                             "written)")
    parser.add_argument("--tones", type=cli.number(0.0, 500.0, "Hz", True, True), nargs="+",
                        metavar="HZ", help="tones to report (default: the notch controller's "
                        "tones found in the bag, else the 3 strongest peaks)")
    parser.add_argument("--control-on", type=cli.number(0.0, cli.MAX_RUN_S, "s"), metavar="S",
                        default=None, help="sim time (s) control went on (default: from the bag)")
    parser.add_argument("--window", type=cli.number(0.0, 3600.0, "s", low_open=True),
                        default=None, metavar="S",
                        help="spectrum window length (s; default: the run's, else "
                             f"{DEFAULT_WINDOW_S:g} s)")
    parser.add_argument("--harmonics-of", type=cli.number(0.0, 500.0, "Hz", high_open=True),
                        default=None, metavar="HZ",
                        help="also report harmonic distortion of this fundamental")
    parser.add_argument("--scenario", default=None,
                        help="name written into report.json (default: the run's, else the "
                             "bag directory's name)")
    parser.add_argument("--model", type=cli.existing_file, default=None,
                        help="physical model YAML for the Jacobian (default: packaged)")
    parser.add_argument("--twin", type=cli.existing_dir, default=None, metavar="TWIN_BAG",
                        help="the same run with control never on (experiment --twin's "
                             "DIR/twin/bag): report.json gets a 'twin' section comparing the "
                             "controlled window with the same samples of the twin")
    parser.add_argument("--twin-segment", type=cli.number(0.0, 60.0, "s", low_open=True),
                        default=DEFAULT_TWIN_SEGMENT_S, metavar="S",
                        help="window (s) of the following tones' reduction over time "
                             f"(default {DEFAULT_TWIN_SEGMENT_S:g})")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (2 on bad input, with the reason on stderr)."""
    args = build_parser().parse_args(argv)
    from hexapod_vibration.analysis.bag_analysis import analyze_bag
    from hexapod_vibration.analysis.bag_files import BagError
    from hexapod_vibration.analysis.report import Request
    from hexapod_vibration.analysis.report_tables import (
        format_following,
        format_harmonics,
        format_table,
    )
    from hexapod_vibration.analysis.report_windows import WindowTooShort
    from hexapod_vibration.core.model.config import load_model_config

    try:
        model = load_model_config(args.model or config_path("pph_model.yaml"))
        request = Request(args.tones, args.scenario, args.window, args.harmonics_of)
        with outputs.staged(args.out) as staging:     # every file complete, or none
            result = analyze_bag(args.bag, staging, model, request, args.control_on,
                                 plots=not args.no_plots, twin_bag=args.twin,
                                 twin_segment_s=args.twin_segment)
    except (BagError, WindowTooShort, ValueError, FileNotFoundError) as exc:
        return cli.fail("analyze", exc)
    except KeyboardInterrupt as exc:
        print("analyze: interrupted; nothing written", file=sys.stderr, flush=True)
        return cli.interrupted_exit_code(exc)
    print(format_table(result.report, result.paper_reduction_db))
    following = format_following(result.report)
    if following:
        print(following)
    if args.twin is not None:
        from hexapod_vibration.analysis.twin import format_twin

        print(format_twin(result.report))
    if result.harmonics is not None:
        print(format_harmonics(result.harmonics, result.report["scenario"]))
    for note in result.details["notes"]:
        print(f"note: {note}")
    print(f"wrote {args.out / 'report.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
