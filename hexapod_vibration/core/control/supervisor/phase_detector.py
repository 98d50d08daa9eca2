"""The tracker's phase detector: the weights' turning over a block says where the line is.

Weights that follow a line off their oscillator turn at the offset (paper eq. 21). Each
block the detector compares the canceller's adapted weights with the last block's, through
the plant's response G and P^-1 at the oscillators
(:func:`~hexapod_vibration.core.control.frequency_tracker.weight_phase_error`), combines the
orders of each tone and gives the tracker the phase error of each fundamental. Until the
weights settled after adaptation started (:data:`SETTLE_TIME_CONSTANTS` of the slowest
tone) the tones coast on the acquired rate; then the detector's gain rises to 1 over
:data:`DETECTOR_RAMP_TIME_CONSTANTS`.
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.frequency_tracker import (
    SETTLE_TIME_CONSTANTS,
    FrequencyTracker,
    combine_orders,
    weight_phase_error,
)
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.core.control.supervisor.retuning import norm_ratio

DETECTOR_RAMP_TIME_CONSTANTS = 1.0
"""After the settling, the phase detector's gain rises linearly to 1 over this many
adaptation time constants (1/mu samples)."""


class PhaseDetector:
    """The weights of the last block, since when they adapt, G and P^-1 at the oscillators.

    Args:
        settings: the settings in force (the adaptation mode).
        canceller: the canceller whose weights are read.
        plant: what the identifications found (G, G(f)).
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 plant: PlantKnowledge) -> None:
        """No weights seen, not adapting."""
        self._settings = settings
        self._canceller = canceller
        self._plant = plant
        self.previous_w: np.ndarray | None = None
        """The adapted weights (T, C) (N) at the last block's end, None: none to compare."""
        self.adapting_since = -1
        """The sample adaptation (output on, not frozen) runs since (-1: it does not)."""
        self.matrices: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
        """G and P^-1 (T, C, C) at the oscillators the last time P changed."""
        self._source: np.ndarray | None = None
        self._rate_scale = 1.0

    def stop(self) -> None:
        """The tones hold (an identification): no weights to compare, not adapting."""
        self.previous_w, self.adapting_since = None, -1

    def adaptation_rate(self) -> float:
        """The rate the weights adapt at now (mu; 0 while off or frozen)."""
        canceller = self._canceller
        return canceller.mu if canceller.enabled and not canceller.frozen else 0.0

    def adaptation_started(self, index: int) -> bool:
        """Note when adaptation runs since (sample ``index`` if it starts now: True)."""
        if self.adaptation_rate() <= 0.0:
            self.adapting_since = -1
            return False
        if self.adapting_since >= 0:
            return False
        self.adapting_since = index
        return True

    def step(self, index: int, tracker: FrequencyTracker, orders: np.ndarray, tones: int,
             block: int, p_at_hz: np.ndarray) -> np.ndarray | None:
        """The tracker's frequencies (Hz) for the next block; None: adaptation starts now.

        ``orders``: the orders of each of the ``tones`` tones in the bank (order-major
        rows); ``block``: the samples between two calls; ``p_at_hz``: where P was computed.
        """
        canceller = self._canceller
        weights = canceller.adapted_weights      # the update low-pass's lag left out
        previous, self.previous_w = self.previous_w, weights
        t = tones
        if self.adaptation_started(index):
            return None
        rate = self.adaptation_rate()
        plant, inverse = self._matrices(p_at_hz)
        effective = rate * self._rate_scale               # a mu policy's per-tone rates
        if (previous is None or plant is None or rate <= 0.0
                or index - self.adapting_since < SETTLE_TIME_CONSTANTS / effective):
            # still settling after adaptation started: the tones coast on the acquired
            # rate (frozen or not adapting: they hold)
            return tracker.update(np.zeros(t), np.zeros(t, bool), effective,
                                  coast=rate > 0.0 and plant is not None)
        error, strength = weight_phase_error(previous, weights, rate, block, plant, inverse)
        strength = np.where(canceller.adapting, strength, 0.0)
        fundamental_error, valid = combine_orders(error.reshape(-1, t),
                                                  strength.reshape(-1, t), orders)
        # the detector's gain rises from 0 to 1 over the next time constant: the weights
        # are not converged yet and their first measurements kick the loop
        elapsed = (index - self.adapting_since) * effective - SETTLE_TIME_CONSTANTS
        fundamental_error = fundamental_error * min(1.0, elapsed / DETECTOR_RAMP_TIME_CONSTANTS)
        return tracker.update(fundamental_error, valid, effective)

    def _matrices(self, p_at_hz: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """G and P^-1 (T, C, C) at the oscillators for the phase detector (None: no G yet).

        G is the broadband response at the frequencies P was last computed for, else the
        tone-identified one; P^-1 is recomputed when the canceller's P changes.
        """
        p = self._canceller.coefficients_view
        if self._source is not p:
            g = self._plant.response
            if self._plant.frequency_response is not None and g is not None:
                g = self._plant.frequency_response.at(p_at_hz)
            if g is None or g.shape != p.shape:
                return None, None
            try:
                self.matrices = (g, np.linalg.inv(p))
                normal = adaptation.normalized_coefficients(g, self._settings.config.adaptation)
            except (ValueError, np.linalg.LinAlgError):
                return None, None
            # the rate each tone adapts at relative to mu: |P| / |P normalised on G|, the
            # slowest of the fundamentals' orders (the settling waits for it)
            self._rate_scale = float(np.clip(norm_ratio(p, normal).min(), 1e-6, None))
            self._source = p
        return self.matrices
