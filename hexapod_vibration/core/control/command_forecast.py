"""The notch controller's commands for the next samples, for a driver to apply when one is late.

In realtime a command can miss its deadline (a process descheduled, a stall): the driver
then held the previous command, a step in a 40 Hz sinusoid that kicks every band, or after
``timeout_samples`` applied zero force. The divergence guard saw those kicks as control
making things worse and faded control out (docs/performance.md). What the controller will
command is known ahead, though: the canceller's output is a sum of sinusoids whose weights
move slowly (``u_n+k = g Re{sum_t W_t e^{j (phi_t + k dphi_t)}}``), and an identification's
excitation is a fixed schedule. :func:`notch_forecast` gives the next samples' commands
with the weights, frequencies and output gain as they are now; the notch controller
publishes it (``contract.NOTCH_FORECAST_TOPIC``) and a realtime driver applies its row for a
sample whose command is late (:class:`~hexapod_vibration.core.loop.forecast_buffer.
ForecastBuffer`).

Exact while the canceller's weights stand still (control off, an identification's
excitation, the output's enable and fade ramps: ``test/core/test_command_forecast.py``).
While it adapts, the error of the row k samples ahead is the weights' change over k samples
less their trend: the forecast moves the weights at their rate over the last
``TREND_BASELINE_SAMPLES`` (:class:`WeightTrend`) for up to ``TREND_HORIZON_SAMPLES``. A
stand-in's error is a one-sample step of the force, a broadband kick that the divergence
guard judges in its quiet third octaves (0.02-0.1 N lifted a 250-sample block of the 100 or
251 Hz band by 11-20 dB in realtime runs). Measured on the core loop's
``single_tone_harmonic`` (forecast every 10 samples, error against the commands then
computed): in the first second of control the worst error 10 samples ahead fell from
0.155 N (weights and gain held) to 0.026 N, rms 0.024 -> 0.004 N; after 3 s 0.0018 ->
0.0014 N. The trend over 10 samples did as well at first but, once converged, amplified
the weights' noise (rms 0.0005 against 0.0003 N held); over 50 it lagged (0.043 N). Tones
fading out after a change of the tone set are left out (they last
``DEFAULT_RAMP_SAMPLES``).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller

TREND_HORIZON_SAMPLES = 20
"""Samples over which the weights' trend is extrapolated; held beyond (a converging weight
approaches its value exponentially: a line beyond a few forecasts' spans overshoots)."""
TREND_BASELINE_SAMPLES = 30
"""The weights' trend is their change over at least this many samples (over 10, from one
forecast to the next, the weights' noise made it worse than none once converged)."""
MAX_TREND_SPAN_SAMPLES = 200
"""Longest span (samples) over which the weights' change is a trend."""


class WeightTrend:
    """The canceller's weights' change per sample, over the last forecasts."""

    def __init__(self) -> None:
        """No weights seen yet."""
        self._history: deque[tuple[int, np.ndarray]] = deque()

    def rate(self, weights: np.ndarray, sample: int) -> np.ndarray | None:
        """The weights' change per sample ((T, C) N) over ``TREND_BASELINE_SAMPLES``.

        From the newest weights kept that are at least that old; None (no trend) before
        there are any, after a change of the tone set, or when they are more than
        ``MAX_TREND_SPAN_SAMPLES`` old or ``sample`` is not after the last call.
        """
        history, sample = self._history, int(sample)
        weights = np.array(weights, copy=True)
        if history and (history[-1][0] >= sample or history[-1][1].shape != weights.shape):
            history.clear()
        while len(history) > 1 and sample - history[1][0] >= TREND_BASELINE_SAMPLES:
            history.popleft()
        history.append((sample, weights))
        then, old = history[0]
        span = sample - then
        if not TREND_BASELINE_SAMPLES <= span <= MAX_TREND_SPAN_SAMPLES:
            return None
        return (weights - old) / span


def canceller_ahead(canceller: AdaptiveNotchCanceller, samples: int,
                    weight_rate: np.ndarray | None = None) -> np.ndarray:
    """The canceller's commands (N, (samples, C)) for its next ``samples`` samples.

    Row 0 is the sample its next :meth:`~AdaptiveNotchCanceller.step` answers, with the
    output gain along its ramp (:meth:`~AdaptiveNotchCanceller.gains_ahead`) and the
    weights at their present values, or, with ``weight_rate`` ((T, C) per sample, a
    :class:`WeightTrend`), moving at that rate for up to ``TREND_HORIZON_SAMPLES``.
    """
    samples = int(samples)
    steps = np.outer(np.arange(samples), canceller.phase_steps_rad)
    oscillators = np.exp(1j * (canceller.phases_rad + steps))               # (samples, T)
    rows = (oscillators @ canceller.weights).real
    if weight_rate is not None:
        moves = np.minimum(np.arange(1, samples + 1), TREND_HORIZON_SAMPLES)
        rows += moves[:, None] * (oscillators @ weight_rate).real
    return canceller.gains_ahead(samples)[:, None] * rows


def notch_forecast(canceller: AdaptiveNotchCanceller, identifier: object | None,
                   samples: int, weight_rate: np.ndarray | None = None) -> np.ndarray:
    """The notch controller's commands (N, (samples, C)) for its next ``samples`` samples.

    Args:
        canceller: The controller's canceller.
        identifier: The identification run injecting its excitation (with an
            ``excitation_ahead(samples)``), or None.
        samples: How many samples ahead (>= 1).
        weight_rate: The weights' trend (:class:`WeightTrend`), or None (held).
    """
    rows = canceller_ahead(canceller, samples, weight_rate)
    if identifier is not None:
        rows += identifier.excitation_ahead(samples)
    return rows
