"""The type-2 update for sweeping tones: on while a tone sweeps, its rates with the sweep.

A sweeping tone (the reference's slope or the tracker's learnt rate above
:data:`SWEEP_RATE_FLOOR_HZ_PER_S`) adapts with a type-2 update (the weights' rate of change
integrated too, :data:`~.rate_policy.MOVING_TONE_DAMPING`) that follows the disturbance's
change as the tone moves through the plant's response; steady tones keep the paper's
update.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.rate_policy import (
    RatePolicy,
    moving_tone_integral_ratio,
)

INTEGRAL_DELAY_TIME_CONSTANTS = 5.0
"""The type-2 update starts this many adaptation time constants (1/mu samples) after the
tones start adapting with output on: integrating the initial convergence's large residual
would overshoot (spin_up_tachometer, integrating from control on: 14 and 42 dB on order 1
in the first two seconds, 24 and 62 dB first order)."""
SWEEP_HOLD_TIME_CONSTANTS = 10.0
"""A tone that stopped sweeping keeps its type-2 update this many time constants (1/mu_t
samples) before it is cleared: without the tachometer the tracker's rate falls ahead of the
weights, whose rate is still unlearning the tracker's lag at the sweep's end (spin_up,
cleared at once: 46/39/36 dB on orders 1-3 in the second after; held: 55/49/44 dB, the
first-order update 50/42/40 dB)."""
SWEEP_CHECK_BLOCKS = 4
"""The type-2 update's gating and its rates' scaling with the sweep run every this many
blocks (64 ms): the sweep rate and the holds (time constants, >= 0.17 s) change slowly,
and each check costs some 20 small array operations."""
SWEEP_RATE_FLOOR_HZ_PER_S = 0.05
"""A tone whose fundamental moves faster than this (Hz/s) sweeps: it adapts with the type-2
update, and its weights' rates of change are scaled with its sweep rate when that falls
(:meth:`SweepGate.follow`)."""


class SweepGate:
    """Switches the canceller's type-2 update per tone with the sweep; scales its rates.

    Args:
        settings: the settings in force (whether the tones may move).
        canceller: the canceller whose integral ratios and weight rates are set.
        rates: the rate policy (a mu policy's per-tone rates).
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 rates: RatePolicy) -> None:
        """No sweep known."""
        self._settings = settings
        self._canceller = canceller
        self._rates = rates
        self.sweep_hz_per_s: np.ndarray | None = None
        """Each fundamental's sweep rate (Hz/s) at the last check, None: unknown."""
        self._integrating_from = -1
        self._swept_at: np.ndarray | None = None

    def restart(self) -> None:
        """New settings: the paper's update until the tones sweep again, after the delay."""
        self._integrating_from = -1
        self._canceller.set_integral_ratio(0.0)

    def gate(self, index: int) -> None:
        """Type-2 update for the tones that sweep, once they adapted with output a while.

        A tone sweeps when its fundamental moves faster than
        :data:`SWEEP_RATE_FLOOR_HZ_PER_S` (the reference's slope, or the tracker's learnt
        rate), and for :data:`SWEEP_HOLD_TIME_CONSTANTS` after. Off (the weights' rates
        cleared) for steady tones, while the canceller is frozen, off or ramping, and above
        the ``mu`` the Nyquist test found it stable at (:attr:`RatePolicy.type2_max_mu`); on
        :data:`INTEGRAL_DELAY_TIME_CONSTANTS` time constants after that ended. (A steady
        tone keeps the paper's update: with the tracker closing its loop on the weights'
        rotation, a type-2 update on a steady 1 % mismatch left 40-48 dB where the
        first-order update has 56-66 dB.)
        """
        canceller = self._canceller
        running = (canceller.enabled and not canceller.frozen and canceller.mu > 0.0
                   and canceller.output_gain == 1.0 and bool(np.all(canceller.adapting)))
        ratio = (moving_tone_integral_ratio(self._settings.config)
                 if canceller.mu <= self._rates.type2_max_mu else 0.0)
        sweep = self.sweep_hz_per_s
        size = canceller.tone_frequencies_hz.size
        if not running or ratio <= 0.0 or sweep is None or size % max(sweep.size, 1):
            self._integrating_from, self._swept_at = -1, None
            if canceller.integrating:
                canceller.set_integral_ratio(0.0)
            return
        if self._integrating_from < 0:
            self._integrating_from = index + int(np.ceil(INTEGRAL_DELAY_TIME_CONSTANTS
                                                         / canceller.mu))
        if index < self._integrating_from:
            return
        if self._swept_at is None or self._swept_at.shape != sweep.shape:
            self._swept_at = np.full(sweep.shape, -np.inf)
        fast = np.abs(sweep) > SWEEP_RATE_FLOOR_HZ_PER_S
        if not fast.any() and bool(np.all(np.isneginf(self._swept_at))):
            return                             # steady tones: the paper's update
        self._swept_at[fast] = index
        scale = np.broadcast_to(self._rates.tone_rate_scale(), (size,))  # kappa_t = R mu_t
        hold = SWEEP_HOLD_TIME_CONSTANTS / (canceller.mu * np.maximum(scale, 1e-6))
        sweeping = index - np.tile(self._swept_at, size // sweep.size) <= hold
        wanted = ratio * scale * sweeping
        if not np.array_equal(wanted, canceller.integral_ratio):
            canceller.set_integral_ratio(wanted)

    def follow(self, sweep_hz_per_s: np.ndarray | None) -> None:
        """Scale the weights' rates of change (type-2 update) down with a falling sweep rate.

        While a tone sweeps, its weights' rate of change is the converged weight's slope
        over frequency times the sweep rate (Hz/s: the reference's slope, or the tracker's
        learnt rate): when the sweep slows or stops (a spin-up reaching its speed), the
        rate the integrator learnt is scaled by the ratio of the new to the old sweep rate
        (within 0..1) instead of running on until the residual unlearns it. Only for
        tones that were sweeping faster than :data:`SWEEP_RATE_FLOOR_HZ_PER_S`.
        """
        canceller = self._canceller
        previous = self.sweep_hz_per_s
        self.sweep_hz_per_s = None if sweep_hz_per_s is None else np.asarray(
            sweep_hz_per_s, dtype=float).copy()
        if (previous is None or sweep_hz_per_s is None
                or previous.shape != self.sweep_hz_per_s.shape
                or not canceller.integrating):
            return
        sweeping = np.abs(previous) > SWEEP_RATE_FLOOR_HZ_PER_S
        if not np.any(sweeping):
            return
        factor = np.ones(previous.size)
        factor[sweeping] = np.clip(self.sweep_hz_per_s[sweeping] / previous[sweeping],
                                   0.0, 1.0)
        if np.all(factor == 1.0):
            return
        orders = canceller.tone_frequencies_hz.size // previous.size
        rates = canceller.weight_rates * np.tile(factor, orders)[:, None]
        canceller.set_weight_rates(rates)
