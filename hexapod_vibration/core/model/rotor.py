"""Rotating-machine disturbance (reaction wheel, pump, cryocooler): harmonic orders of a speed.

The rotor turns at a speed (Hz, revolutions per second) that follows a piecewise-linear
profile in time (knots ``profile_time_s``, ``profile_speed_hz``; held constant before the
first knot and after the last). Each harmonic order ``h`` (may be non-integer, as reaction
wheel harmonics are) sounds at ``h * speed`` with an amplitude that scales with the speed
squared from its value at ``reference_speed_hz`` (the Masterson reaction-wheel model):

    F(t) = sum_h A_h (speed(t) / reference_speed_hz)^2 sin(2 pi h Phi(t) + phase_h)

where ``Phi(t)`` is the integral of the speed from t = 0 (revolutions), computed exactly
(the speed is piecewise linear, so ``Phi`` is piecewise quadratic). The force acts along z
at the shaker's point (:class:`~hexapod_vibration.core.model.shaker.Shaker` adds it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def _finite_array(name: str, values: Sequence[float]) -> np.ndarray:
    """A 1-D float array of ``values``; ValueError naming ``name`` if any is not finite."""
    array = np.asarray(values, float).reshape(-1)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"rotor {name} must be finite, got {list(array)}")
    return array


class Rotor:
    """A rotor's speed profile and harmonic orders; force (N), speed and frequencies (Hz)."""

    def __init__(self, orders: Sequence[float], amplitudes_n: Sequence[float],
                 reference_speed_hz: float, profile_time_s: Sequence[float],
                 profile_speed_hz: Sequence[float],
                 phases_rad: Sequence[float] | None = None) -> None:
        """Validate and store the rotor; ValueError with a one-line reason otherwise.

        ``orders`` (> 0) and ``amplitudes_n`` (>= 0 N peak at ``reference_speed_hz``) are
        parallel; ``profile_time_s`` (>= 0 s, strictly increasing) and ``profile_speed_hz``
        (>= 0 Hz) are parallel with at least one knot; ``phases_rad`` empty or one per order.
        """
        self.orders = _finite_array("orders", orders)
        self.amplitudes_n = _finite_array("amplitudes_n", amplitudes_n)
        if self.orders.size == 0:
            raise ValueError("a rotor needs at least one harmonic order")
        if self.orders.size != self.amplitudes_n.size:
            raise ValueError(f"{self.orders.size} rotor orders but {self.amplitudes_n.size} "
                             "amplitudes: the arrays must have the same length")
        if np.any(self.orders <= 0.0):
            raise ValueError(f"rotor orders must be > 0, got {list(self.orders)}")
        if np.any(self.amplitudes_n < 0.0):
            raise ValueError(f"rotor amplitudes must be >= 0 N, got {list(self.amplitudes_n)}")
        phases = _finite_array("phases_rad", phases_rad if phases_rad is not None else ())
        if phases.size not in (0, self.orders.size):
            raise ValueError("rotor phases must be empty or one per order")
        self.phases_rad = phases if phases.size else np.zeros(self.orders.size)
        if not (np.isfinite(reference_speed_hz) and reference_speed_hz > 0.0):
            raise ValueError(f"rotor reference speed must be > 0 Hz, got {reference_speed_hz}")
        self.reference_speed_hz = float(reference_speed_hz)
        self._set_profile(_finite_array("profile_time_s", profile_time_s),
                          _finite_array("profile_speed_hz", profile_speed_hz))

    def _set_profile(self, times_s: np.ndarray, speeds_hz: np.ndarray) -> None:
        """Check the knots and precompute the exact phase integral at each of them."""
        if times_s.size == 0 or times_s.size != speeds_hz.size:
            raise ValueError(f"rotor profile: {times_s.size} times and {speeds_hz.size} speeds "
                             "(need the same number, at least one)")
        if np.any(times_s < 0.0) or np.any(np.diff(times_s) <= 0.0):
            raise ValueError("rotor profile times must be >= 0 s and strictly increasing")
        if np.any(speeds_hz < 0.0):
            raise ValueError(f"rotor profile speeds must be >= 0 Hz, got {list(speeds_hz)}")
        if times_s[0] > 0.0:      # speed held from t = 0 to the first knot
            times_s = np.concatenate([[0.0], times_s])
            speeds_hz = np.concatenate([[speeds_hz[0]], speeds_hz])
        self.profile_time_s, self.profile_speed_hz = times_s, speeds_hz
        # Slope (Hz/s) of each segment; the one after the last knot holds the speed.
        self._slope = np.append(np.diff(speeds_hz) / np.diff(times_s), 0.0)
        spans = np.diff(times_s)
        revolutions = speeds_hz[:-1] * spans + 0.5 * self._slope[:-1] * spans**2
        self._revolutions_at_knot = np.concatenate([[0.0], np.cumsum(revolutions)])

    def _segment(self, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment index, time into it (s) and its slope (Hz/s; 0 before the first knot).

        ``searchsorted(..., side="right") - 1`` lies in [-1, knots - 1]: only the lower
        bound needs clamping (``np.maximum``, a third of ``np.clip``'s cost per call).
        """
        index = np.maximum(np.searchsorted(self.profile_time_s, time_s, side="right") - 1, 0)
        into_s = time_s - self.profile_time_s[index]
        slope = np.where(into_s < 0.0, 0.0, self._slope[index])
        return index, into_s, slope

    def _speed(self, index: np.ndarray, into_s: np.ndarray, slope: np.ndarray) -> np.ndarray:
        """Speed (Hz) ``into_s`` seconds into segment ``index`` of slope ``slope``."""
        return self.profile_speed_hz[index] + slope * into_s

    def _revolutions(self, index: np.ndarray, into_s: np.ndarray,
                     slope: np.ndarray) -> np.ndarray:
        """Revolutions from t = 0 to ``into_s`` seconds into segment ``index``."""
        return (self._revolutions_at_knot[index] + self.profile_speed_hz[index] * into_s
                + 0.5 * slope * into_s**2)

    def speed_hz(self, time_s: np.ndarray | float) -> np.ndarray:
        """Rotor speed (Hz, revolutions per second) at the given times (s)."""
        return self._speed(*self._segment(np.asarray(time_s, float)))

    def revolutions(self, time_s: np.ndarray | float) -> np.ndarray:
        """Integral of the speed from t = 0 to ``time_s`` (revolutions), exact."""
        return self._revolutions(*self._segment(np.asarray(time_s, float)))

    def frequencies_hz(self, time_s: np.ndarray | float) -> np.ndarray:
        """Frequency (Hz) of every order at the given times: shape ``time_s.shape + (orders,)``."""
        return self.speed_hz(time_s)[..., None] * self.orders

    def force_n(self, time_s: np.ndarray | float) -> np.ndarray:
        """Rotor force (N) at the given times (s), same shape as ``time_s``.

        One segment lookup for the speed and the phase (the plant calls this every sample).
        """
        segment = self._segment(np.asarray(time_s, float))
        scale = (self._speed(*segment) / self.reference_speed_hz) ** 2
        phase = (2.0 * np.pi) * self._revolutions(*segment)[..., None] * self.orders
        return scale * (np.sin(phase + self.phases_rad) @ self.amplitudes_n)


def rotor_or_none(orders: Sequence[float], amplitudes_n: Sequence[float],
                  reference_speed_hz: float, profile_time_s: Sequence[float],
                  profile_speed_hz: Sequence[float]) -> Rotor | None:
    """A :class:`Rotor`, or None when ``orders`` and ``amplitudes_n`` are both empty (no rotor)."""
    if len(orders) == 0 and len(amplitudes_n) == 0:
        return None
    return Rotor(orders, amplitudes_n, reference_speed_hz, profile_time_s, profile_speed_hz)
