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

Exact while the canceller's weights and gain stand still (control off, an identification's
excitation: ``test/core/test_command_forecast.py``); while it adapts, the error of the row k
samples ahead is the weights' change over k samples. Tones fading out after a change of the
tone set are left out (they last ``DEFAULT_RAMP_SAMPLES``).
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller


def canceller_ahead(canceller: AdaptiveNotchCanceller, samples: int) -> np.ndarray:
    """The canceller's commands (N, (samples, C)) for its next ``samples`` samples.

    Row 0 is the sample its next :meth:`~AdaptiveNotchCanceller.step` answers, with the
    weights and output gain frozen at their present values.
    """
    steps = np.outer(np.arange(int(samples)), canceller.phase_steps_rad)
    phases = canceller.phases_rad + steps                                   # (samples, T) rad
    return canceller.output_gain * (np.exp(1j * phases) @ canceller.weights).real


def notch_forecast(canceller: AdaptiveNotchCanceller, identifier: object | None,
                   samples: int) -> np.ndarray:
    """The notch controller's commands (N, (samples, C)) for its next ``samples`` samples.

    Args:
        canceller: The controller's canceller.
        identifier: The identification run injecting its excitation (with an
            ``excitation_ahead(samples)``), or None.
        samples: How many samples ahead (>= 1).
    """
    rows = canceller_ahead(canceller, samples)
    if identifier is not None:
        rows += identifier.excitation_ahead(samples)
    return rows
