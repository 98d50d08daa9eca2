"""The loop line of the experiment's table: missed samples and what stood in for them."""

import pytest

from hexapod_vibration.analysis.late_commands import late_since
from hexapod_vibration.analysis.report_tables import loop_missed_text

pytestmark = pytest.mark.unit


def test_missed_alone_and_with_the_notchs_gaps_and_the_forecasts():
    assert loop_missed_text({"missed_samples": 0}) == "0 missed"
    assert loop_missed_text({"missed_samples": 5, "notch_missed_samples": 3}) == (
        "5 missed (3 not received by the notch)")
    assert loop_missed_text({"missed_samples": 5, "notch_missed_samples": 3,
                             "forecast_rows": 4}) == (
        "5 missed (3 not received by the notch; 4 late commands stood in for by forecasts)")
    assert loop_missed_text({"missed_samples": 5, "forecast_rows": 4}) == (
        "5 missed (4 late commands stood in for by forecasts)")
    assert loop_missed_text({"missed_samples": 5, "stand_in_samples": 2}) == (
        "5 missed (2 samples with a force no controller computed)")
    assert loop_missed_text({"missed_samples": 900, "control_on_samples": 20000,
                             "control_on_missed_samples": 31,
                             "control_on_counted_from": 22000}) == (
        "900 missed (31 late of the 20000 from sample 22000, control on)")


def _report(sample: int, late: int) -> dict[str, str]:
    """A driver report on /diagnostics as the bag holds it (strings)."""
    return {"sample": str(sample), "samples": str(sample), "late_commands": str(late)}


def test_late_since_counts_from_the_first_report_at_or_after_the_sample():
    reports = [_report(1000, 4), _report(2000, 10), _report(3000, 812), _report(4000, 815),
               _report(5000, 820)]
    assert late_since(reports, 3000) == (3000, 2000, 8)    # the report at 3000 itself
    assert late_since(reports, 2500) == (3000, 2000, 8)    # nothing before the sample counts
    assert late_since(reports, 500) == (1000, 4000, 816)
    assert late_since(reports, 5000) == (5000, 0, 0)
    assert late_since(reports, 5001) is None               # no report that late
    assert late_since([], 0) is None
