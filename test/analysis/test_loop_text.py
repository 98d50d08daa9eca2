"""The loop line of the experiment's table: missed samples and what stood in for them."""

import pytest

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
