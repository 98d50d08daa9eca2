"""Moving the oscillators: every order to its fundamental, a new P where G(f) says so.

The oscillators move phase-continuously and keep their weights; the guard's tone bands
follow them. With a broadband G(f), a tone that moved by :data:`P_RETUNE_HZ` has its
coefficients checked against G(f) there, and replaced only when they would change by
:data:`P_RETUNE_CHANGE` (keeping each tone's own rate: a mu policy folds per-tone rates
into P).
"""

from __future__ import annotations

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.divergence_guard import DivergenceGuard
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge

P_RETUNE_HZ = 0.05
"""A moved oscillator's coefficients are checked against the broadband G(f) after this
shift (Hz)."""
P_RETUNE_CHANGE = 0.1
"""...and replaced only when some tone's P would change by this fraction of its norm (about
6 degrees of phase): a tone drifting +-1 Hz at 40 Hz then keeps its P (each replacement
kicks the phase detector: third octave 56-71 Hz +1.15 dB over the uncontrolled twin at a
P every 0.05 Hz, +0.59 dB with this), one sweeping 30 -> 150 Hz gets a new P every few
tenths of a hertz (``spin_up`` unchanged, within 0.3 dB per order)."""


def norm_ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T,) ||a_t|| / ||b_t|| of two (T, C, C) stacks (Frobenius; b_t = 0 counts as tiny)."""
    return (np.linalg.norm(a, axis=(1, 2))
            / np.maximum(np.linalg.norm(b, axis=(1, 2)), 1e-300))


class Retuner:
    """Moves the canceller's oscillators and the guard's bands; P follows G(f).

    Args:
        settings: the settings in force (the adaptation mode).
        canceller: the canceller retuned.
        guard: the divergence guard whose tone bands follow.
        plant: what the identifications found (G(f)).
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 guard: DivergenceGuard, plant: PlantKnowledge) -> None:
        """P computed nowhere yet."""
        self._settings = settings
        self._canceller = canceller
        self._guard = guard
        self._plant = plant
        self.p_at_hz: np.ndarray | None = None
        """The oscillators' frequencies (Hz) the canceller's P was computed for."""

    def move(self, bank: np.ndarray) -> None:
        """Every oscillator to ``bank`` (Hz), P as it is (computed there by the caller)."""
        self._canceller.retune(bank)
        self._guard.follow_tones(bank)
        self.p_at_hz = bank

    def retune(self, bank: np.ndarray) -> None:
        """Every oscillator to ``bank`` (Hz); a new P from G(f) if it moved (see the module).

        Only P moves; the weights are left to the adaptation. Carrying them through the
        plant's change of response (W -> G_new^-1 G_old W) assumed the disturbance at the
        accelerometers does not change with the frequency, but it comes through the same
        structure (and a rotor's grows with the speed squared); each carry was a step of
        the output that the adaptation then undid. Measured on the core loop against the
        uncontrolled twin, last 10 s of ``drift_tracking``, seeds 4/11/12: largest
        third-octave rise +3.1/+2.8/+3.5 dB (44.7-56.2 Hz) with the carry, +1.2/+0.6/+0.7 dB
        without; the tone's band 1 dB better without; ``spin_up`` order 1 over the ramp
        46 -> 52 dB median.
        """
        canceller = self._canceller
        canceller.retune(bank)
        self._guard.follow_tones(bank)
        response = self._plant.frequency_response
        if (response is None or self._plant.response is None
                or np.max(np.abs(bank - self.p_at_hz)) < P_RETUNE_HZ
                or not np.all(canceller.adapting)):     # tones waiting for identification
            return
        try:
            g_old, g_new = response.at(self.p_at_hz), response.at(bank)
            mode = self._settings.config.adaptation
            coefficients = adaptation.normalized_coefficients(g_new, mode)
            # keep each tone's own rate (a mu policy folds per-tone rates into P)
            reference = adaptation.normalized_coefficients(g_old, mode)
            present = canceller.coefficients_view
            coefficients = coefficients * norm_ratio(present, reference)[:, None, None]
        except (ValueError, np.linalg.LinAlgError):     # G(f) unusable there: keep P
            return
        if np.max(norm_ratio(coefficients - present, present)) < P_RETUNE_CHANGE:
            return
        canceller.set_coefficients(coefficients)
        self.p_at_hz = bank
