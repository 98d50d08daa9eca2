"""``/pph/*_forecast`` messages: what a controller writes reads back, a bad one is refused.

The publisher sends a forecast every ``FORECAST_EVERY_SAMPLES`` samples while someone listens
(in-process nodes on the test's domain).
"""

from __future__ import annotations

import numpy as np
import pytest

from hexapod_vibration.contract import (
    FORECAST_EVERY_SAMPLES,
    FORECAST_PHASE_SAMPLES,
    FORECAST_ROWS_LABEL,
    FORECAST_SAMPLES,
    InvalidStrutMessage,
)
from hexapod_vibration.ros.command_forecasts import (
    ForecastPublisher,
    parse_forecast,
    subscribe_forecasts,
)
from hexapod_vibration.ros.messages import make_vector_array

RUN = 77
HANG_GUARD_S = 30.0


@pytest.mark.unit
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
@pytest.mark.unit
def test_a_bad_forecast_is_refused(message):
    with pytest.raises(InvalidStrutMessage):
        parse_forecast(message)


@pytest.mark.parametrize("phase", [0, 5])
def test_the_publisher_sends_a_forecast_every_tenth_sample(ros_context, phase):
    """At its phase: the two controllers' forecasts fall on different samples."""
    controller = ros_context.create_node("forecaster")
    driver = ros_context.create_node("forecast_reader")
    got: list[tuple[int, int]] = []
    subscribe_forecasts(driver, "/pph/test_forecast",
                        lambda rows, first, _run: got.append((first, rows.shape[0])))
    publisher = ForecastPublisher(controller, "/pph/test_forecast", phase)
    assert ros_context.wait_for(lambda: publisher._publisher.get_subscription_count() > 0,
                                HANG_GUARD_S)
    for index in range(5, 26):
        publisher.after(index, RUN, lambda k: np.full((k, 6), float(k)))
    expected = [(n + 1, FORECAST_SAMPLES) for n in range(5, 26)
                if n % FORECAST_EVERY_SAMPLES == phase]
    assert ros_context.wait_for(lambda: len(got) >= len(expected), HANG_GUARD_S)
    assert got == expected


@pytest.mark.unit
def test_the_controllers_forecast_on_different_samples():
    """One sample carrying both forecasts made its commands late (FORECAST_PHASE_SAMPLES)."""
    phases = [p % FORECAST_EVERY_SAMPLES for p in FORECAST_PHASE_SAMPLES.values()]
    assert sorted(FORECAST_PHASE_SAMPLES) == ["notch_controller", "pointing_controller"]
    assert len(set(phases)) == len(phases)
