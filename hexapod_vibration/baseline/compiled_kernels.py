"""Compiled (numba) per-sample kernels of the notch and the FxLMS: their arithmetic cost.

In NumPy a controller step is a handful of array calls, each with a fixed interpreter
cost of about half a microsecond, so at the sizes of this product (6 channels, a few
tones, 32-128 taps) the time per sample measures the number of calls rather than the
arithmetic (``hexapod_bench`` reports that floor). The paper's efficiency claim is about
arithmetic: a few operations per tone and strut for the notch against the model-based
filtered-x LMS's ``K*I*J*(L + N)``. This module compiles the steady-state step of both
controllers to machine code with numba, as a DSP or C implementation would run them, and
processes a block of error samples in one call, so the per-sample time is the arithmetic
cost alone.

The kernels are the same algorithms as :class:`~hexapod_vibration.core.control.notch.
AdaptiveNotchCanceller` (diagonal ``P``, enabled, no ramps or fading tones) and
:class:`~hexapod_vibration.baseline.fxlms.FilteredXLMSController` (enabled, no leakage),
including the phasor re-synchronisation, the FxLMS warm-up and the update order; the tests
check their commands against those classes sample by sample. They feed the errors open
loop (a block of given errors), which does not change the cost: no branch depends on the
data. They are benchmark instruments, not used by the nodes.

Each constructor copies the controller's present state, so the NumPy object is never
modified.
"""

from __future__ import annotations

import numba
import numpy as np

from hexapod_vibration.baseline.fxlms import FilteredXLMSController
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.phasor import TWO_PI, PhasorBank


@numba.njit(cache=False, fastmath=True)
def _resync(z: np.ndarray, phi0: np.ndarray, dphi: np.ndarray, amp: np.ndarray,
            samples: int) -> None:
    """PhasorBank._sync: move the phase grid by ``samples`` and set ``z`` exactly."""
    for t in range(z.size):
        phi0[t] = (phi0[t] + dphi[t] * float(samples)) % TWO_PI
        z[t] = amp[t] * complex(np.cos(phi0[t]), np.sin(phi0[t]))


@numba.njit(cache=False, fastmath=True)
def _notch_block(v: np.ndarray, q: np.ndarray, z: np.ndarray, rot: np.ndarray,
                 phi0: np.ndarray, dphi: np.ndarray, amp: np.ndarray, since: np.ndarray,
                 resync_at: int, errors: np.ndarray, out: np.ndarray) -> None:
    """Notch steps (diagonal P) over the rows of ``errors`` (m/s^2), commands into ``out`` (N)."""
    n_ch, n_tones = v.shape
    for n in range(errors.shape[0]):
        for i in range(n_ch):
            e = errors[n, i]
            acc = 0.0
            for t in range(n_tones):
                w = v[i, t] + q[i, t] * (e * z[t])          # V += conj(mu P) e e^{j phi}
                v[i, t] = w
                acc += w.real * z[t].real + w.imag * z[t].imag
            out[n, i] = acc
        # rotation and count written out in both kernels: as a called (even inlined)
        # njit function they cost the notch 6x2 0.049 instead of 0.024 us per sample
        for t in range(n_tones):
            z[t] = z[t] * rot[t]
        since[0] += 1
        if since[0] == resync_at:
            _resync(z, phi0, dphi, amp, since[0])
            since[0] = 0


@numba.njit(cache=False, fastmath=True)
def _fxlms_block(paths_rev: np.ndarray, w: np.ndarray, x_lin: np.ndarray, r_lin: np.ndarray,
                 heads: np.ndarray, mu: float, z: np.ndarray, rot: np.ndarray,
                 phi0: np.ndarray, dphi: np.ndarray, amp: np.ndarray, since: np.ndarray,
                 resync_at: int, errors: np.ndarray, out: np.ndarray) -> None:
    """FxLMS steps over the rows of ``errors`` (m/s^2), commands into ``out`` (N).

    ``paths_rev`` (J, I, L) holds S[i, j, L - 1 - a] at ``a`` (oldest lag first), so that
    each filtered reference is one contiguous dot product with the reference history
    ``x_lin`` (K, 2H): a mirrored ring (every sample written at ``h`` and ``h + H``) whose
    slice ``[h + 1, h + H]`` is the last H samples, oldest first. ``r_lin`` (I, 2N, K*J)
    is a mirrored ring of filtered references written at decreasing rows ``p`` and
    ``p + N``, so rows ``[p, p + N)`` are ``r[n], ..., r[n - N + 1]``, contiguous with the
    weights ``w`` (N, K*J). ``heads`` holds ``h``, ``p`` and the warm-up samples left.
    """
    n_act, n_err, n_path = paths_rev.shape
    n_taps, n_kj = w.shape
    n_tones = z.size
    depth = x_lin.shape[1] // 2
    w_flat = w.reshape(n_taps * n_kj)
    for n in range(errors.shape[0]):
        hx = (heads[0] + 1) % depth
        p = (heads[1] - 1) % n_taps
        heads[0], heads[1] = hx, p
        newest = hx + depth
        for k in range(n_tones):                                      # x_k[n]
            x_lin[k, hx] = z[k].real
            x_lin[k, newest] = z[k].real
        first = newest - n_path + 1
        for k in range(n_tones):                                      # r_kji[n]
            # slices keep the inner loops free of numba's negative-index checks, so
            # LLVM vectorises them
            window = x_lin[k, first:first + n_path]
            for i in range(n_err):
                for j in range(n_act):
                    path = paths_rev[j, i]
                    acc = 0.0
                    for a in range(n_path):
                        acc += path[a] * window[a]
                    r_lin[i, p, k * n_act + j] = acc
                    r_lin[i, p + n_taps, k * n_act + j] = acc
        if heads[2] > 0:
            heads[2] -= 1
        elif mu > 0.0:
            for i in range(n_err):                                    # W -= mu e r[n - m]
                g = mu * errors[n, i]
                r_window = r_lin[i, p:p + n_taps].reshape(n_taps * n_kj)
                for q in range(n_taps * n_kj):
                    w_flat[q] -= g * r_window[q]
        for j in range(n_act):                                        # u_j[n]
            out[n, j] = 0.0
        for m in range(n_taps):
            for k in range(n_tones):
                xv = x_lin[k, newest - m]
                for j in range(n_act):
                    out[n, j] += w[m, k * n_act + j] * xv
        for k in range(n_tones):
            z[k] = z[k] * rot[k]
        since[0] += 1
        if since[0] == resync_at:
            _resync(z, phi0, dphi, amp, since[0])
            since[0] = 0


class _CompiledPhasors:
    """The state of a :class:`~hexapod_vibration.core.control.phasor.PhasorBank`, copied."""

    def __init__(self, bank: PhasorBank) -> None:
        """Copy phasors, rotations, phase grid, amplitudes and the re-sync counter."""
        t = bank.z.size
        self.z = bank.z.copy()
        self.rot = bank._rot[:t].copy()
        self.phi0 = bank._phi0.copy()
        self.dphi = bank._dphi.copy()
        self.amp = bank._amp.copy()
        self.since = np.array([bank._since], dtype=np.int64)
        self.resync_at = int(bank._resync_at)


class CompiledNotch:
    """The steady-state notch step (diagonal P, enabled, gain 1), compiled.

    Args:
        canceller: the notch whose state (weights, coefficients, phasors) is copied.

    Raises:
        ValueError: full P, disabled, frozen, ramping or fading: states the kernel does
            not model.
    """

    def __init__(self, canceller: AdaptiveNotchCanceller) -> None:
        """Copy the state; ValueError for states the kernel does not model."""
        c = canceller
        if (c._q is None or not c.enabled or c.frozen or c.output_gain != 1.0
                or c._fading.active or c.mu <= 0.0 or c.integrating
                or c.update_lowpass_hz > 0.0):
            raise ValueError("the compiled notch models only an adapting, enabled notch "
                             "with diagonal P, output gain 1, no fading tones, the paper's "
                             "first-order update and no update low-pass")
        self.n_channels = c.n_channels
        self._v = c._v.copy()
        self._q = c._q.copy()
        self._osc = _CompiledPhasors(c._osc)

    def run(self, errors: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Steps over the (n, C) errors (m/s^2); the (n, C) commands (N) go into ``out``."""
        o = self._osc
        _notch_block(self._v, self._q, o.z, o.rot, o.phi0, o.dphi, o.amp, o.since,
                     o.resync_at, errors, out)
        return out


class CompiledFxlms:
    """The FxLMS step (enabled, no leakage), compiled, from a freshly built controller.

    Args:
        controller: a :class:`FilteredXLMSController` that has not stepped yet (its
            histories are zero); its paths, tones, amplitudes, ``mu`` and taps are copied.

    Raises:
        ValueError: the controller has stepped, is disabled or frozen, or has leakage.
    """

    def __init__(self, controller: FilteredXLMSController) -> None:
        """Copy the model and settings; ValueError for states the kernel does not model."""
        f = controller
        fresh = f._warmup == f._nl + f._n_taps - 1 and f._hist.pos == f._hist.block + 1
        if not fresh or not f.enabled or f._frozen or f._keep != 1.0:
            raise ValueError("the compiled FxLMS starts from a fresh, enabled, adapting "
                             "controller without leakage")
        k, n = f._freqs.size, f._n_taps
        self.n_channels = f._ni           # error channels I (commands: J = f._nj)
        self._paths_rev = np.ascontiguousarray(
            f.secondary_paths.transpose(1, 0, 2)[:, :, ::-1])
        self._w = np.zeros((n, k * f._nj))
        self._x_lin = np.zeros((k, 2 * max(f._nl, n)))
        self._r_lin = np.zeros((f._ni, 2 * n, k * f._nj))
        self._heads = np.array([-1, 0, f._warmup], dtype=np.int64)
        self._mu = float(f.mu)
        self._osc = _CompiledPhasors(f._osc)

    def run(self, errors: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Steps over the (n, I) errors (m/s^2); the (n, J) commands (N) go into ``out``."""
        o = self._osc
        _fxlms_block(self._paths_rev, self._w, self._x_lin, self._r_lin, self._heads,
                     self._mu, o.z, o.rot, o.phi0, o.dphi, o.amp, o.since,
                     o.resync_at, errors, out)
        return out

