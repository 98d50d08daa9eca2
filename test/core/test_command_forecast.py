"""The notch controller's forecast of its next commands, and the driver applying it when late.

The forecast (core/control/command_forecast.py) against the commands the canceller and the
identifications then give (exact while the weights stand still), and a driver's arbiter
applying its rows to a supervisor's late commands (core/loop/command_arbiter.py).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from hexapod_vibration.core.control.adaptation import ToneResponseIdentifier
from hexapod_vibration.core.control.command_forecast import (
    MAX_TREND_SPAN_SAMPLES,
    TREND_BASELINE_SAMPLES,
    WeightTrend,
    canceller_ahead,
    notch_forecast,
)
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.plant_identification import BroadbandIdentifier
from hexapod_vibration.core.loop.command_arbiter import CommandArbiter, Refusal

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from linear_plants import FS, late_notch_rig  # noqa: E402

pytestmark = pytest.mark.unit
AHEAD = 50


def _next_commands(step, samples):
    return np.array([np.array(step(np.zeros(6)), copy=True) for _ in range(samples)])


def test_canceller_forecast_is_its_next_outputs_with_weights_still():
    rng = np.random.default_rng(1)
    canceller = AdaptiveNotchCanceller(6, [40.0, 80.0, 123.4], FS, mu=0.0)
    canceller.set_weights(rng.normal(size=(3, 6)) + 1j * rng.normal(size=(3, 6)))
    _next_commands(canceller.step, 37)
    forecast = canceller_ahead(canceller, AHEAD)
    np.testing.assert_allclose(forecast, _next_commands(canceller.step, AHEAD), atol=1e-12)


@pytest.mark.parametrize(("flag", "smooth"), [(True, False), (True, True), (False, True)])
def test_canceller_forecast_follows_the_output_ramp(flag, smooth):
    rng = np.random.default_rng(2)
    canceller = AdaptiveNotchCanceller(6, [40.0, 80.0], FS, mu=0.0)
    canceller.set_weights(rng.normal(size=(2, 6)) + 1j * rng.normal(size=(2, 6)))
    if not flag:
        _next_commands(canceller.step, 300)          # fully on, then faded out
    canceller.set_enabled(flag, ramp_samples=120, smooth=smooth)
    for done in (0, 7, 40, 100):                     # across the ramp and its end
        _next_commands(canceller.step, done)
        forecast = canceller_ahead(canceller, AHEAD, WeightTrend().rate(canceller.weights, 0))
        np.testing.assert_allclose(forecast, _next_commands(canceller.step, AHEAD), atol=1e-12)


def test_weight_trend_is_the_change_per_sample_over_its_baseline():
    trend, weights = WeightTrend(), np.ones((2, 6), complex)
    span = TREND_BASELINE_SAMPLES
    assert trend.rate(weights, 10) is None                           # nothing before
    assert trend.rate(weights * 2.0, 10 + span - 1) is None          # too short a span
    np.testing.assert_allclose(trend.rate(weights * 3.0, 10 + span), np.full((2, 6), 2 / span))
    np.testing.assert_allclose(trend.rate(weights * 3.5, 10 + 2 * span - 1),
                               np.full((2, 6), 1.5 / span))   # from 10 + span - 1
    assert trend.rate(weights, 10 + 2 * span - 1) is None            # not after the last
    assert trend.rate(np.ones((3, 6), complex), 500) is None         # a new tone set
    assert trend.rate(np.ones((3, 6), complex), 500 + MAX_TREND_SPAN_SAMPLES + 1) is None


@pytest.mark.parametrize("make", [
    lambda: BroadbandIdentifier(6, FS, period_s=0.5, settle_s=0.1, periods=2),
    lambda: ToneResponseIdentifier(6, [40.0, 80.0], FS, settle_s=0.01, measure_s=0.03),
])
def test_identification_forecast_is_its_excitation_across_segments_and_the_end(make):
    identifier = make()
    starts = list(range(0, identifier.total_samples + AHEAD, 17))
    done = 0
    for start in starts:
        _next_commands(identifier.step, start - done)
        done = start
        forecast = identifier.excitation_ahead(AHEAD)
        probe = make()
        _next_commands(probe.step, start)
        np.testing.assert_allclose(forecast, _next_commands(probe.step, AHEAD), atol=1e-12)
    assert identifier.done


def _stalled_loop(forecasts: bool, samples: int = 16_000, trend: bool = True):
    """A notch supervisor on a 6-channel plant whose driver gets 2 % of its commands late.

    Returns the supervisor, the commands it computed and the notch forces applied (N, by
    sample), and the late samples.
    """
    (a, b, c), supervisor, arbiter, late, rng = late_notch_rig(samples)
    x = np.zeros(a.shape[0])
    shaker = (0.02 * np.sin(2 * np.pi * 40.0 * np.arange(samples) / FS)[:, None]
              + 1e-4 * rng.normal(size=(samples, 6)))
    computed, applied = np.zeros((samples, 6)), np.zeros((samples, 6))
    weights = WeightTrend()
    for n in range(samples):
        computed[n] = supervisor.step(n, c @ x + shaker[n])
        if not late[n]:
            arbiter.offer("notch", computed[n].copy(), n, 1, 0.0)
            if forecasts and n % 10 == 0:
                identifier = supervisor.identification.identifier
                rate = (weights.rate(supervisor.canceller.weights, n) if trend else None)
                arbiter.forecast("notch", n + 1, notch_forecast(
                    supervisor.canceller, identifier, AHEAD, rate), 1)
        forces, _ = arbiter.close_sample(False, 5)
        applied[n] = forces["notch"]
        x = a @ x + b @ forces["notch"]
        arbiter.advance()
    return supervisor, computed, applied, late, arbiter


def test_forecasts_stand_in_for_late_commands_in_identification_and_control():
    """Forecasts stand in for the late commands of a supervisor's run.

    No reports of held commands: with forecasts the identification succeeds (without them
    it is refused, test_held_inputs) and the late samples under control get nearly the
    command the canceller computed; a hold of the last command would be far off.
    """
    supervisor, computed, applied, late, arbiter = _stalled_loop(forecasts=True)
    events = [e.message for e in supervisor.drain_events()]
    assert not any("identification failed" in e for e in events), events
    assert supervisor.state in ("adapting", "enabled"), events
    on = 11_000                            # the 10 s identification and its analysis done
    samples = np.arange(on, computed.shape[0] - 1)
    stand_in = samples[late[samples]]
    forecast_error = np.abs(applied[stand_in + 1] - computed[stand_in]).max()   # delay 1
    last_on_time = np.maximum.accumulate(np.where(late, 0, np.arange(late.size)))
    hold_error = np.abs(computed[last_on_time[stand_in]] - computed[stand_in]).max()
    peak = np.abs(computed[on:]).max()
    print(f"{stand_in.size} late samples under control: worst |applied - computed| "
          f"{forecast_error:.3g} N with the forecast, {hold_error:.3g} N with a hold, of "
          f"{peak:.3g} N; {arbiter.streams['notch'].forecast.applied} rows applied")
    assert stand_in.size > 50
    assert forecast_error < 0.01 * peak < hold_error


def test_the_weights_trend_makes_the_stand_ins_closer_while_the_canceller_converges():
    """The same stalled run with the forecast's weights held and moving at their trend.

    The stand-ins of the first two seconds of control (the weights converging) against the
    commands computed for them: the trend's error is the smaller (rms and worst).
    """
    errors = {}
    for trend in (False, True):
        supervisor, computed, applied, late, _ = _stalled_loop(True, 13_000, trend)
        on = 11_000                        # the 10 s identification and its analysis done
        samples = np.arange(on, computed.shape[0] - 1)
        stand_in = samples[late[samples]]
        error = applied[stand_in + 1] - computed[stand_in]
        errors[trend] = (np.sqrt(np.mean(error**2)), np.abs(error).max())
    print(f"stand-in error rms / worst (N): held weights {errors[False]}, trend {errors[True]}")
    assert errors[True][0] < 0.5 * errors[False][0] and errors[True][1] < errors[False][1]


def test_arbiter_applies_forecast_rows_only_for_late_realtime_samples():
    arbiter = CommandArbiter(("notch",), ("notch",), 1, 70.0, delay_samples=1)
    arbiter.refresh_connections({"notch": 1}, 5)
    rows = np.arange(1.0, 31.0).reshape(5, 6)                     # samples 1..5
    assert arbiter.forecast("notch", 1, rows, 1) is None
    assert arbiter.forecast("notch", 0, rows * 0.0, 1) is None    # older: dropped
    arbiter.offer("notch", np.full(6, 9.0), 0, 1, 0.0)
    forces = []
    for _ in range(8):                       # the command for 0 applies at 1, then late
        forces.append(arbiter.close_sample(lockstep=False, timeout_samples=5)[0]["notch"])
        arbiter.advance()
    np.testing.assert_array_equal(forces[1], np.full(6, 9.0))
    for n in range(2, 7):                    # due 1..5: the forecast's rows
        np.testing.assert_array_equal(forces[n], rows[n - 2])
    np.testing.assert_array_equal(forces[7], np.zeros(6))          # due 6: none, stale
    assert arbiter.streams["notch"].forecast.applied == 5
    values, _, _ = arbiter.report(1.0, lockstep=False)
    assert values["notch_forecast_applied"] == 5 and values["notch_late"] == 6
    assert arbiter.forecast("notch", 9, rows * 100.0, 1) is Refusal.OUT_OF_RANGE
    assert arbiter.forecast("notch", 9, rows, 2) is Refusal.OTHER_RUN


def test_lockstep_never_applies_a_forecast():
    arbiter = CommandArbiter(("notch",), ("notch",), 1, 70.0)
    arbiter.refresh_connections({"notch": 1}, 5)
    arbiter.offer("notch", np.full(6, 9.0), 0, 1, 0.0)
    arbiter.forecast("notch", 1, np.ones((5, 6)), 1)
    arbiter.close_sample(lockstep=True, timeout_samples=5)
    arbiter.advance()
    forces, _ = arbiter.close_sample(lockstep=True, timeout_samples=5)
    np.testing.assert_array_equal(forces["notch"], np.full(6, 9.0))  # held
