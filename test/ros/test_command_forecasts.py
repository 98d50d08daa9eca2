"""``/pph/*_forecast`` messages: what a controller writes reads back, a bad one is refused.

The publisher sends a forecast every ``FORECAST_EVERY_SAMPLES`` samples while someone listens,
when its loop is idle (in-process nodes on the test's domain).
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
from hexapod_vibration.core.loop.idle_work import IdleWork
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
    idle_work, last = IdleWork(), [-1]
    publisher = ForecastPublisher(controller, "/pph/test_forecast", phase,
                                  lambda k: np.full((k, 6), float(k)), idle_work,
                                  lambda: (last[0], RUN))
    assert ros_context.wait_for(lambda: publisher._publisher.get_subscription_count() > 0,
                                HANG_GUARD_S)
    for index in range(5, 26):
        last[0] = index                   # the controller acted on it
        publisher.after(index)
        idle_work.run()                   # the loop idle after every sample
    expected = [(n + 1, FORECAST_SAMPLES) for n in range(5, 26)
                if n % FORECAST_EVERY_SAMPLES == phase]
    assert ros_context.wait_for(lambda: len(got) >= len(expected), HANG_GUARD_S)
    assert got == expected


def test_a_deferred_forecast_starts_after_the_last_sample_answered(ros_context):
    """Run late (the loop busy meanwhile), a forecast is of the state then.

    Its first row is the sample after the last one answered; once, however often asked for.
    """
    controller = ros_context.create_node("late_forecaster")
    driver = ros_context.create_node("late_forecast_reader")
    got: list[tuple[int, int | None, float]] = []
    subscribe_forecasts(driver, "/pph/test_forecast",
                        lambda rows, first, run: got.append((first, run, rows[0, 0])))
    idle_work = IdleWork()
    last = [0, RUN]                       # the controller's last sample: index, run
    publisher = ForecastPublisher(controller, "/pph/test_forecast", 0,
                                  lambda k: np.full((k, 6), last[0] + 1.0), idle_work,
                                  lambda: (last[0], last[1]))
    assert ros_context.wait_for(lambda: publisher._publisher.get_subscription_count() > 0,
                                HANG_GUARD_S)
    for index in range(10, 33):           # asked for after 10, 20 and 30
        last[:] = [index, RUN + index // 30]
        publisher.after(index)
    assert idle_work.pending and got == []
    assert idle_work.run() == 1
    assert ros_context.wait_for(lambda: got, HANG_GUARD_S)
    assert got == [(33, RUN + 1, 33.0)]


@pytest.mark.unit
def test_the_controllers_forecast_on_different_samples():
    """One sample carrying both forecasts made its commands late (FORECAST_PHASE_SAMPLES)."""
    phases = [p % FORECAST_EVERY_SAMPLES for p in FORECAST_PHASE_SAMPLES.values()]
    assert sorted(FORECAST_PHASE_SAMPLES) == ["notch_controller", "pointing_controller"]
    assert len(set(phases)) == len(phases)
