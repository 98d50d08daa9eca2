"""A bank of rotating complex phasors: the tones' ``cos``/``sin`` at one multiply per sample.

Both controllers need, every sample, ``e^{j phi_t,n}`` for each tone ``t`` on the wrapped
phase grid ``phi_t,n+1 = (phi_t,n + dphi_t) mod 2 pi`` (rad). Evaluating ``cos`` and ``sin``
costs two transcendental calls per tone and sample; :class:`PhasorBank` instead rotates the
phasor by ``e^{j dphi_t}`` (one complex multiply per tone and sample) and re-synchronises
it exactly to the phase grid every :data:`RESYNC_SAMPLES` samples, so rounding never
accumulates: between two re-synchronisations the phasor stays within a few 1e-14 of
``a_t e^{j phi_t}``. The phase grid itself advances by ``k * dphi_t`` at each
re-synchronisation (``k`` samples at once, one rounding per ``k`` samples instead of one
per sample).
"""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi
RESYNC_SAMPLES = 256


class PhasorBank:
    """Phasors ``z_t = a_t e^{j phi_t}`` of T tones, advanced one sample per :meth:`rotate`.

    Args:
        dphi_rad: phase increments per sample dphi_t (rad), (T,).
        phases_rad: phases phi_t of the present sample (rad), (T,); default 0.
        amplitudes: amplitudes a_t (dimensionless), (T,); default 1.
        resync_samples: samples between exact re-synchronisations (>= 1).

    The array :attr:`z` is updated in place: views of it (``z.real``,
    ``z.view(float)``) taken once stay valid for the object's lifetime.
    """

    def __init__(self, dphi_rad: np.ndarray, phases_rad: np.ndarray | None = None,
                 amplitudes: np.ndarray | None = None,
                 resync_samples: int = RESYNC_SAMPLES) -> None:
        """Allocate the phasors and set them exactly to ``a_t e^{j phi_t}``."""
        self._dphi = np.array(dphi_rad, dtype=float).reshape(-1)
        t = self._dphi.size
        self._phi0 = np.zeros(t) if phases_rad is None else np.remainder(
            np.array(phases_rad, dtype=float).reshape(t), TWO_PI)
        self._amp = np.ones(t) if amplitudes is None else np.array(
            amplitudes, dtype=float).reshape(t)
        if int(resync_samples) < 1:
            raise ValueError(f"resync_samples must be >= 1, got {resync_samples!r}")
        self._resync_at = int(resync_samples)
        # storage of at least two phasors: numpy's in-place ufuncs take a ~2x slower path
        # on one-element arrays; the spare phasor (1, rotated by 1) is never read
        self._rot = np.ones(max(t, 2), dtype=complex)
        self._rot[:t] = np.exp(1j * self._dphi)
        self._rot_t = self._rot[:t]
        self._store = np.ones(max(t, 2), dtype=complex)
        self._scaled = bool(np.any(self._amp != 1.0))
        self._step = np.zeros(t)
        self.z = self._store[:t]
        self._z_re, self._z_im = self.z.real, self.z.imag
        self._since = 0
        self._sync()

    def rotate(self) -> None:
        """Advance every phasor by one sample (one complex multiply per tone)."""
        np.multiply(self._store, self._rot, out=self._store)
        self._since += 1
        if self._since == self._resync_at:
            self._sync()

    def advance(self, samples: int) -> None:
        """Advance by ``samples`` (>= 0) samples at O(T) cost, exactly on the phase grid."""
        self._since += int(samples)
        self._sync()

    def retune(self, dphi_rad: np.ndarray) -> None:
        """Change the phase increments from the next sample on; the phase is continuous.

        The phase grid is first moved exactly by the samples since the last
        re-synchronisation at the old increments, then the new increments (rad/sample,
        (T,)) take over: no phase step, O(T) cost.
        """
        self._sync()
        self._dphi[...] = dphi_rad
        np.multiply(self._dphi, 1j, out=self._rot_t)
        np.exp(self._rot_t, out=self._rot_t)

    def _sync(self) -> None:
        """Move the phase grid by the samples since the last sync; set z exactly (no alloc)."""
        if self._since:
            np.multiply(self._dphi, float(self._since), out=self._step)
            np.add(self._phi0, self._step, out=self._phi0)
            np.remainder(self._phi0, TWO_PI, out=self._phi0)
            self._since = 0
        np.cos(self._phi0, out=self._z_re)
        np.sin(self._phi0, out=self._z_im)
        if self._scaled:
            np.multiply(self._z_re, self._amp, out=self._z_re)
            np.multiply(self._z_im, self._amp, out=self._z_im)

    @property
    def phases_rad(self) -> np.ndarray:
        """Phases phi_t (rad, in [0, 2 pi)) of the present sample, a new array."""
        return np.remainder(self._phi0 + self._since * self._dphi, TWO_PI)

    @property
    def dphi_rad(self) -> np.ndarray:
        """Phase increments (rad/sample), a copy."""
        return self._dphi.copy()

    @property
    def amplitudes(self) -> np.ndarray:
        """Amplitudes a_t, a copy."""
        return self._amp.copy()
