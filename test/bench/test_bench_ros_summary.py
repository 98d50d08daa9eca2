"""The ROS loop benchmark's reporting (bench_ros): pure formatting of measured numbers.

The measurement itself runs the graph for minutes and belongs in ``make bench``; here only
the conversion of the driver's diagnostics into results and the Markdown table.
"""

from __future__ import annotations

import math

from hexapod_vibration.bench.ros_bench import (
    CONFIGURATIONS,
    _realtime_block,
    ros_summary_markdown,
)
from hexapod_vibration.bench.summary import _summary_ros


def _diagnostics(samples: float, late: float, control: tuple | None = None) -> dict:
    """The driver's last report; ``control``: (samples, late) with control in force."""
    stats = {"samples": samples, "late_commands": late, "rate_hz": 999.9, "wall_s": 60.04,
             "period_ms_p50": 1.0, "period_ms_p99": 1.2, "period_ms_max": 3.0,
             "latency_ms_p50": 0.25, "latency_ms_p99": 0.75, "latency_ms_max": 2.0}
    if control is not None:
        stats.update(control_samples=control[0], control_late=control[1],
                     control_missed_fraction=control[1] / control[0])
    return stats


def test_realtime_block_reports_missed_fraction_and_the_layout():
    block = _realtime_block(_diagnostics(60000.0, 30.0), CONFIGURATIONS[0], 60.0)
    assert math.isclose(block["missed_fraction"], 30.0 / 60000.0)
    assert block["missed_samples"] == 30.0
    assert block["duration_s"] == 60.04
    assert block["executor"].startswith("waitset (pph_graph")
    stalled = _realtime_block({"stalled": True}, CONFIGURATIONS[1], 60.0)
    assert stalled["stalled"] and "three processes" in stalled["executor"]


def test_summary_table_and_target_verdicts():
    good = _realtime_block(_diagnostics(60000.0, 30.0), CONFIGURATIONS[0], 60.0)
    bad = _realtime_block(_diagnostics(60000.0, 600.0, (48000, 60)), CONFIGURATIONS[1], 60.0)
    results = {"realtime": good, "lockstep_speedup": 1.7, "loops": {
        "composed/waitset": {"realtime": good, "lockstep": {"speedup": 1.7}},
        "processes/waitset": {"realtime": bad, "lockstep": {"speedup": 1.3}},
        "processes/events": {"realtime": {"stalled": True}, "lockstep": {"stalled": True}}}}
    table = ros_summary_markdown(results).splitlines()
    assert table[2].startswith("| composed/waitset | 60.0 | 999.90 | 0.050 | - | 1.20 |")
    assert "| 1.70 |" in table[2] and "| 1.000 | 0.125 of 48000 |" in table[3]
    assert table[4] == "| processes/events | stalled | | | | | | stalled |"
    text = "\n".join(_summary_ros(results))
    assert "p99 latency under 1 ms: met (0.050 % missed, p99 0.75 ms" in text
    assert "Lockstep at least 3x faster than real time: **not met** (1.70x)" in text
    results["realtime"] = bad
    assert "under 1 ms: **not met** (1.000 % missed" in "\n".join(_summary_ros(results))
    assert "separate processes" not in text            # no CPU budget measured


def test_the_separate_processes_verdict_is_the_fifo_budget_window():
    from hexapod_vibration.bench.summary import FIFO_RECORDER_SETUP

    good = _realtime_block(_diagnostics(60000.0, 30.0), CONFIGURATIONS[0], 60.0)
    results = {"realtime": good, "lockstep_speedup": 1.7,
               "loops": {"composed/waitset": {"realtime": good, "lockstep": {"speedup": 1.7}}}}
    for missed, p99, verdict in ((0.0009, "0.98", "met"), (0.00107, "0.98", "**not met**"),
                                 (0.0005, "1.20", "**not met**")):
        results["budget"] = {FIFO_RECORDER_SETUP: {"wall_s": 30.0, "loop": {
            "missed_fraction": missed, "latency_ms_p99": p99}}}
        line = [t for t in _summary_ros(results) if "separate processes" in t]
        assert len(line) == 1 and f"window): {verdict} ({100 * missed:.3f} % missed" in line[0]
        assert f"p99 {float(p99):.2f} ms over 30.0 s" in line[0]
