"""Multi-tone shaker (Aura AST-1B-4 class): force along z on the bottom plate.

The force is a sum of tones (frequency Hz, amplitude N, phase rad), each optionally with a
slow sinusoidal frequency drift, plus white broadband noise, clipped to the shaker's force
limit; an optional rotating machine (:class:`~hexapod_vibration.core.model.rotor.Rotor`)
mounted at the same point adds its force (its own source: not clipped by the shaker).
Phases are integrated analytically, so the force at any time is exact and vectorized
over the internal steps of a sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hexapod_vibration.core.model.kernel_choice import compiled_kernels
from hexapod_vibration.core.model.rotor import Rotor

_NO_NOISE = np.empty(0)


@dataclass(frozen=True)
class ShakerTone:
    """One tone: frequency (Hz), amplitude (N, peak), phase (rad), drift (Hz peak, s period)."""

    frequency_hz: float
    amplitude_n: float
    phase_rad: float = 0.0
    drift_hz: float = 0.0
    drift_period_s: float = 60.0

    def __post_init__(self) -> None:
        """Validate: positive finite frequency, finite non-negative amplitude and drift."""
        if not np.isfinite(self.frequency_hz) or self.frequency_hz <= 0.0:
            raise ValueError(f"shaker tone frequency must be > 0 Hz, got {self.frequency_hz}")
        if not np.isfinite(self.amplitude_n) or self.amplitude_n < 0.0:
            raise ValueError(f"shaker tone amplitude must be >= 0 N, got {self.amplitude_n}")
        if not np.isfinite(self.phase_rad):
            raise ValueError("shaker tone phase must be finite")
        if not np.isfinite(self.drift_hz) or self.drift_hz < 0.0 or self.drift_period_s <= 0.0:
            raise ValueError("shaker drift must be >= 0 Hz with a period > 0 s")


class Shaker:
    """Force generator: tones + drift + broadband noise, clipped to ``force_limit_n``, + rotor."""

    def __init__(self, tones: Sequence[ShakerTone] = (), noise_rms_n: float = 0.0,
                 force_limit_n: float = 100.0, seed: int = 0, rotor: Rotor | None = None) -> None:
        """Create a shaker; ``noise_rms_n`` is the RMS (N) of white noise at the step rate.

        ``rotor`` (optional) is a rotating machine at the same point: its force (N) is added
        after the shaker's clipping. Without it the force is exactly the shaker's.
        """
        if not np.isfinite(noise_rms_n) or noise_rms_n < 0.0:
            raise ValueError(f"shaker noise RMS must be >= 0 N, got {noise_rms_n}")
        self._rng = np.random.default_rng(seed)
        self.force_limit_n = float(force_limit_n)
        self.noise_rms_n = float(noise_rms_n)
        self.rotor = rotor
        self._kernels = compiled_kernels()
        self.set_tones(tones)

    def set_tones(self, tones: Sequence[ShakerTone]) -> None:
        """Replace the tones (already validated by :class:`ShakerTone`)."""
        tones = list(tones)
        self.tones = tones
        self._f = np.array([t.frequency_hz for t in tones], float)
        self._a = np.array([t.amplitude_n for t in tones], float)
        self._p = np.array([t.phase_rad for t in tones], float)
        self._df = np.array([t.drift_hz for t in tones], float)
        self._tp = np.array([t.drift_period_s for t in tones], float)
        self._w = 2.0 * np.pi * self._f          # rad/s, the first factor of the phase
        self._drifts = bool(np.any(self._df != 0.0))
        self._grid_key: tuple[float, int] | None = None   # see _tone_sum
        self._grid: tuple[np.ndarray, ...] = ()

    def frequencies_hz(self, time_s: np.ndarray | float) -> np.ndarray:
        """True frequency (Hz) of every sounding tone at the given times, shape ``(..., tones)``.

        The shaker's tones (with their drift) first, then the rotor's orders if there is one;
        a tone or order of zero amplitude is silent and left out.
        """
        t = np.asarray(time_s, float)[..., None]
        loud = self._a > 0.0
        shaker = self._f[loud] + self._df[loud] * np.sin(2.0 * np.pi * t / self._tp[loud])
        if self.rotor is None:
            return shaker
        rotor = self.rotor.frequencies_hz(time_s)[..., self.rotor.amplitudes_n > 0.0]
        return np.concatenate([shaker, rotor], axis=-1)

    def force_n(self, time_s: np.ndarray) -> np.ndarray:
        """Force (N) at the given times (s): shaker (one noise draw per time point) + rotor."""
        force = self._shaker_force_n(time_s)
        if self.rotor is not None:
            force += self.rotor.force_n(time_s)
        return force

    def _shaker_force_n(self, time_s: np.ndarray) -> np.ndarray:
        """The shaker's own force (N): tones, drift, noise, clipped."""
        t = np.asarray(time_s, float)[:, None]
        # Instantaneous frequency f + df sin(2 pi t / T): phase integrates it exactly.
        phase = 2.0 * np.pi * self._f * t - self._df * self._tp * np.cos(2.0 * np.pi * t / self._tp)
        force = np.sin(phase + self._p) @ self._a if self._a.size else np.zeros(t.shape[0])
        return self._add_noise_and_limit(force)

    def force_into(self, start_s: float, step_s: float, out: np.ndarray) -> np.ndarray:
        """Write the force (N) at the times ``start_s + step_s * k`` (s) into ``out[k]``.

        The same values and noise draws as ``force_n(start_s + step_s * np.arange(n))``
        for ``n = len(out)``, computed in preallocated buffers; ``out`` must be a
        contiguous float array. Returns ``out``.
        """
        if self._drifts:
            out[:] = self._shaker_force_n(start_s + step_s * np.arange(out.shape[0]))
        elif self._kernels is not None and self._a.size:
            noise = (self._rng.normal(0.0, self.noise_rms_n, out.shape[0])
                     if self.noise_rms_n > 0.0 else _NO_NOISE)
            self._kernels.shaker_tones_into(*self._grid_for(step_s, out.shape[0]), self._a,
                                            start_s, noise, self.force_limit_n, out)
        else:
            if self._a.size:
                self._tone_sum(start_s, step_s, out)
            else:
                out.fill(0.0)
            self._add_noise_and_limit(out)
        if self.rotor is not None:
            out += self.rotor.force_n(start_s + step_s * np.arange(out.shape[0]))
        return out

    def _add_noise_and_limit(self, force: np.ndarray) -> np.ndarray:
        """Add one noise draw per time point and clip to the force limit, in place (N)."""
        if self.noise_rms_n > 0.0:
            np.add(force, self._rng.normal(0.0, self.noise_rms_n, force.shape[0]), out=force)
        np.maximum(force, -self.force_limit_n, out=force)
        return np.minimum(force, self.force_limit_n, out=force)

    def _grid_for(self, step_s: float, steps: int) -> tuple[np.ndarray, ...]:
        """Time offsets (s), angular frequencies (rad/s), phases (rad) and scratch per (step, tone).

        Laid out once per step size and count (the first call of a run).
        """
        key = (step_s, steps)
        if self._grid_key != key:
            offsets_s = step_s * np.arange(steps)
            self._grid = (np.repeat(offsets_s[:, None], self._a.size, axis=1),
                          np.tile(self._w, (steps, 1)), np.tile(self._p, (steps, 1)),
                          np.empty((steps, self._a.size)))
            self._grid_key = key
        return self._grid

    def _tone_sum(self, start_s: float, step_s: float, out: np.ndarray) -> None:
        """Sum of the drift-free tones (N) at ``start_s + step_s * k`` (s), into ``out``.

        Operation for operation what :meth:`force_n` computes when no tone drifts (its
        drift term is then exactly zero), so the result is bit-identical; the time
        offsets, angular frequencies and phases are laid out per (time, tone) once.
        """
        offsets_s, w, phase_rad, scratch = self._grid_for(step_s, out.shape[0])
        np.add(offsets_s, start_s, out=scratch)
        np.multiply(w, scratch, out=scratch)
        np.add(scratch, phase_rad, out=scratch)
        np.dot(np.sin(scratch, out=scratch), self._a, out=out)


def tones_from_arrays(frequencies_hz: Sequence[float], amplitudes_n: Sequence[float],
                      phases_rad: Sequence[float] | None = None,
                      drift_hz: float = 0.0, drift_period_s: float = 60.0) -> list[ShakerTone]:
    """Build tones from parallel arrays (as ROS parameters give them); lengths must match."""
    phases_rad = list(phases_rad) if phases_rad is not None and len(phases_rad) else None
    if len(frequencies_hz) != len(amplitudes_n):
        raise ValueError(f"{len(frequencies_hz)} shaker frequencies but {len(amplitudes_n)} "
                         "amplitudes: the arrays must have the same length")
    if phases_rad is not None and len(phases_rad) != len(frequencies_hz):
        raise ValueError("shaker phases must be empty or as long as the frequencies")
    phases = phases_rad or [0.0] * len(frequencies_hz)
    return [ShakerTone(float(f), float(a), float(p), drift_hz, drift_period_s)
            for f, a, p in zip(frequencies_hz, amplitudes_n, phases, strict=True)]
