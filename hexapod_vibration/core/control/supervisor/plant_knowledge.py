"""What the identifications found: the plant at the tones in force, per tone, over frequency.

A tone identification gives G (C, C) at each of its tones, kept per tone so that a tone
set made of known tones needs no new identification; a broadband one gives G(f) over
0..fs/2 (:class:`~hexapod_vibration.core.control.plant_identification.PlantFrequencyResponse`,
G at any tone from it), the disturbance's spectrum before control and its lines.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.core.control.notch_weights import NotchWeights
from hexapod_vibration.core.control.plant_identification import (
    DisturbanceSpectrum,
    PlantFrequencyResponse,
)


def coefficients_in_force(plant: PlantKnowledge, canceller: NotchWeights) -> bool:
    """Whether the canceller adapts with coefficients: the identified plant's, or raw's P = I.

    The one definition of "adapting" (the ``adapting`` state, the guard watching): ``raw``
    (the paper as printed) adapts without any identification, the normalised modes once
    the plant at their tones is known.
    """
    return plant.response is not None or canceller.adapts


def tone_key(frequency_hz: float) -> float:
    """The key a tone's identified response is kept under (its frequency to 1 uHz)."""
    return round(float(frequency_hz), 6)


class PlantKnowledge:
    """The identified plant: in force at the oscillators, per tone, G(f); the disturbance."""

    def __init__(self) -> None:
        """Nothing identified yet."""
        self.response: np.ndarray | None = None
        """G (T, C, C) at the oscillators in force ((m/s^2)/N), None until identified."""
        self.tones: list[float] = []
        """The oscillators (Hz) :attr:`response` is at ([] while it is None)."""
        self.frequency_response: PlantFrequencyResponse | None = None
        """G(f) of the last identification if it was broadband, else None."""
        self.disturbance: DisturbanceSpectrum | None = None
        """The disturbance's spectrum measured by that broadband identification."""
        self.lines_hz = np.zeros(0)
        """The disturbance lines (Hz) that identification fitted."""
        self.confidence = float("nan")
        """1 - the last identification's relative uncertainty at the tones."""
        self._responses: dict[float, np.ndarray] = {}

    def put_in_force(self, response: np.ndarray | None, tones: list[float]) -> None:
        """G (T, C, C) at ``tones`` (Hz) is the response in force (None: none known)."""
        self.response = response
        self.tones = tones if response is not None else []

    def learn_tones(self, tones: list[float], response: np.ndarray) -> None:
        """A tone identification measured G (T, C, C) at ``tones`` (Hz); no G(f) now."""
        self.frequency_response = None
        self.disturbance = None
        for f, g in zip(tones, response, strict=True):
            self._responses[tone_key(f)] = g

    def learn_broadband(self, response: PlantFrequencyResponse,
                        disturbance: DisturbanceSpectrum) -> None:
        """A broadband identification measured G(f) and the disturbance's spectrum."""
        self.frequency_response = response
        self.disturbance = disturbance

    def known_response(self, tones: list[float]) -> np.ndarray | None:
        """Identified G (T, C, C) at ``tones``, or None if a tone was never identified."""
        if self.frequency_response is not None and tones:
            return self.frequency_response.at(tones)
        rows = [self._responses.get(tone_key(f)) for f in tones]
        if not rows or any(r is None for r in rows):
            return None
        return np.stack(rows)

    def status(self) -> dict[str, Any]:
        """Each oscillator's mean diagonal gain ((m/s^2)/N) and phase (deg), once known."""
        if self.response is None:
            return {}
        diag = np.diagonal(self.response, axis1=1, axis2=2)
        return {"plant_gain_m_s2_per_n": np.round(np.abs(diag).mean(axis=1), 6).tolist(),
                "plant_phase_deg": np.round(np.rad2deg(np.angle(diag.mean(axis=1))),
                                            2).tolist()}
