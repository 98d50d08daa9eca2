"""``/pph/notch_forecast`` messages: what the notch writes reads back, a bad one is refused."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod_vibration.contract import FORECAST_ROWS_LABEL, InvalidStrutMessage
from hexapod_vibration.ros.command_forecasts import parse_forecast
from hexapod_vibration.ros.messages import make_vector_array

pytestmark = pytest.mark.unit
RUN = 77


def test_a_forecast_reads_back_as_it_was_written():
    rows = np.arange(60.0).reshape(10, 6) / 7.0
    parsed, first, run = parse_forecast(make_vector_array(rows.reshape(-1), 1234, RUN,
                                                          label=FORECAST_ROWS_LABEL))
    np.testing.assert_array_equal(parsed, rows)
    assert (first, run) == (1234, RUN)


@pytest.mark.parametrize("message", [
    make_vector_array(np.zeros(12), 9, RUN, label="frequency_hz"),          # another array
    make_vector_array(np.zeros(10), 9, RUN, label=FORECAST_ROWS_LABEL),     # not rows of 6
    make_vector_array(np.zeros(0), 9, RUN, label=FORECAST_ROWS_LABEL),      # no row
    make_vector_array(np.zeros(12), None, label=FORECAST_ROWS_LABEL),       # no first sample
    make_vector_array([np.nan] + [0.0] * 5, 9, RUN, label=FORECAST_ROWS_LABEL),
])
def test_a_bad_forecast_is_refused(message):
    with pytest.raises(InvalidStrutMessage):
        parse_forecast(message)
