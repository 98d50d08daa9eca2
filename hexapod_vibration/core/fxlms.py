"""Multichannel filtered-x LMS (Elliott's multiple-error LMS): the model-based baseline.

The paper compares its Adaptive Notch Canceller with the classic model-based alternative,
the multiple-error LMS of Elliott, Stothers and Nelson (1987). This module implements it
with the same prior knowledge and the same step interface as
:class:`~hexapod_vibration.core.notch.AdaptiveNotchCanceller`, so that both run in the same
loop and their cost per sample can be compared:

- Reference ``x_n = sum_t A_t cos(phi_t,n)`` (dimensionless): the sum of the disturbance
  tones' sinusoids, known frequencies as for the notch.
- Secondary paths ``S[i, j, l]`` (m/s^2 per N): FIR impulse responses (``L`` taps, 32-128)
  from command ``j`` to error ``i``, identified on the running plant before control
  (:class:`SecondaryPathIdentifier`), with the pairing of docs/architecture.md:
  ``e_i[n] = sum_j sum_l S[i, j, l] u_j[n - l] + d_i[n]`` (so ``S[:, :, 0]`` is ~0).
- Control filters ``W[k, j]`` (N per unit reference): one FIR of ``N`` taps per actuator,
  ``u_j[n] = sum_k W[k, j] x[n - k]``.
- Filtered reference ``r_ij[n] = sum_l S[i, j, l] x[n - l]`` and the normalised update
  ``W[k, j] -= mu / (eps + ||R||^2) * sum_i e_i[n] r_ij[n - k]``, with
  ``||R||^2 = sum_{i,j,k} r_ij[n - k]^2`` the filtered-reference power in the filters'
  window (normalised LMS: ``mu`` is dimensionless, stable for small ``mu``).

Cost per sample: ``I*J*L`` multiply-adds for the filtered reference (the model's cost, which
grows with the plant order through ``L``), ``2*I*J*N`` for the update and its normalisation
and ``J*N`` for the output, against O(T*C) for the notch whatever the plant.

:class:`FxlmsCoreLoop` runs a scenario of :mod:`hexapod_vibration.core.closed_loop` with this
controller in place of the notch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.adaptation import SampledRun
from hexapod_vibration.core.closed_loop import STRUTS, CoreLoop, LoopRecord
from hexapod_vibration.core.model_config import ModelConfig
from hexapod_vibration.core.notch import TWO_PI, validate_frequencies, validate_mu
from hexapod_vibration.core.scenario import Scenario

DEFAULT_PATH_TAPS = 64
DEFAULT_CONTROL_TAPS = 32
PATH_TAPS_RANGE = (32, 128)
DEFAULT_FXLMS_MU = 0.05
NORMALISATION_EPS = 1e-12


def _check_positive_int(name: str, value: int) -> int:
    v = int(value)
    if v != value or v < 1:
        raise ValueError(f'{name} must be a positive integer, got {value!r}')
    return v


def fir_frequency_response(paths: np.ndarray, freqs_hz: Sequence[float] | np.ndarray,
                           sample_rate_hz: float) -> np.ndarray:
    """Complex response G[t, i, j] = sum_l S[i, j, l] e^{-j w_t l} of FIR paths.

    This is the phasor of error ``i`` per unit phasor of command ``j`` in the convention of
    docs/architecture.md, directly comparable with
    :class:`~hexapod_vibration.core.adaptation.ToneResponseIdentifier`.

    Args:
        paths: (I, J, L) impulse responses (m/s^2 per N per tap).
        freqs_hz: tones (Hz).
        sample_rate_hz: sample rate (Hz).

    Returns:
        Complex (T, I, J) array (m/s^2 per N).
    """
    s = np.asarray(paths, dtype=float)
    f = np.asarray(freqs_hz, dtype=float).reshape(-1)
    lags = np.arange(s.shape[2])
    kernel = np.exp(-1j * TWO_PI * f[:, None] * lags[None, :] / sample_rate_hz)
    return np.einsum('ijl,tl->tij', s, kernel)


class SecondaryPathIdentifier(SampledRun):
    """FIR secondary-path identification on a running plant, one actuator at a time.

    Same step interface as the canceller (error of sample n in, command of sample n out).
    The run has C segments of ``settle_s + measure_s``; in segment j only actuator j is
    driven, by a seeded random binary sequence of +-``amplitude_n`` (white, crest factor 1,
    so the actuator limits are respected). At the end of each segment the error of its last
    ``measure_s`` is fitted by least squares on the lagged excitation
    ``u_j[n], ..., u_j[n - L + 1]`` (its history before the segment is zero, as applied),
    plus a constant and ``cos/sin`` of the ``nuisance_frequencies_hz`` (the known disturbance
    tones, so a running shaker does not bias the estimate). ``settle_s`` lets the previous
    segment's response decay. With 6 channels and the defaults the run takes
    6 x 0.8 s = 4.8 s.

    Args:
        n_channels: number of actuators and errors C.
        sample_rate_hz: sample rate fs (Hz).
        n_taps: FIR length L (taps), in [32, 128].
        amplitude_n: excitation level (N), the binary sequence's +- value.
        settle_s: discarded time at the start of each segment (s).
        measure_s: fitted time per segment (s); needs well over L + 2T + 1 samples.
        nuisance_frequencies_hz: disturbance tones fitted and removed (Hz).
        seed: seed of the excitation sequence.
    """

    def __init__(self, n_channels: int, sample_rate_hz: float,
                 n_taps: int = DEFAULT_PATH_TAPS, amplitude_n: float = 2.0,
                 settle_s: float = 0.1, measure_s: float = 0.7,
                 nuisance_frequencies_hz: Sequence[float] | np.ndarray = (),
                 seed: int = 0) -> None:
        """Validate the arguments (ValueError) and pre-generate the excitation."""
        self._c = _check_positive_int('n_channels', n_channels)
        self._fs = float(sample_rate_hz)
        if not np.isfinite(self._fs) or self._fs <= 0.0:
            raise ValueError(f'sample_rate_hz must be finite and > 0, got {sample_rate_hz!r}')
        self._taps = _check_positive_int('n_taps', n_taps)
        lo, hi = PATH_TAPS_RANGE
        if not lo <= self._taps <= hi:
            raise ValueError(f'n_taps must be in [{lo}, {hi}], got {n_taps}')
        if not np.isfinite(amplitude_n) or amplitude_n <= 0.0:
            raise ValueError(f'amplitude_n must be finite and > 0, got {amplitude_n!r}')
        self._nuisance = validate_frequencies(nuisance_frequencies_hz, self._fs)
        self._settle = int(round(settle_s * self._fs))
        self._measure = int(round(measure_s * self._fs))
        n_par = self._taps + 1 + 2 * self._nuisance.size
        if self._settle < 0 or self._measure < 4 * n_par:
            raise ValueError(f'settle_s must be >= 0 and measure_s must hold >= 4 x {n_par} '
                             f'samples (L + 1 + 2T parameters), got {self._measure}')
        self._seg_len = self._settle + self._measure
        self._total = self._c * self._seg_len
        rng = np.random.default_rng(seed)
        self._excitation = amplitude_n * rng.choice([-1.0, 1.0], size=(self._c, self._seg_len))
        self._errors = np.zeros((self._measure, self._c))
        self._paths = np.zeros((self._c, self._c, self._taps))
        self._u = np.zeros(self._c)
        self._n = 0

    def step(self, error: np.ndarray) -> np.ndarray:
        """Record the error of sample n (m/s^2, (C,)) and return the command (N, (C,))."""
        position = self._position(error)
        if position is None:
            return self._u.copy()
        e, seg, k = position
        if k >= self._settle:
            self._errors[k - self._settle] = e
            if k == self._seg_len - 1:
                self._paths[:, seg, :] = self._fit(seg)
        self._u[seg] = self._excitation[seg, k]
        self._n += 1
        return self._u.copy()

    def _fit(self, seg: int) -> np.ndarray:
        """Least-squares FIR (C, L) from actuator ``seg`` to every error."""
        taps, fs = self._taps, self._fs
        padded = np.concatenate([np.zeros(taps - 1), self._excitation[seg]])
        # row r is sample k = settle + r of the segment; column l holds u[k - l]
        lagged = np.lib.stride_tricks.sliding_window_view(padded, taps)[:, ::-1]
        lagged = lagged[self._settle:self._settle + self._measure]
        n_abs = seg * self._seg_len + self._settle + np.arange(self._measure)
        phase = TWO_PI * self._nuisance[None, :] * n_abs[:, None] / fs
        regress = np.hstack([lagged, np.ones((self._measure, 1)), np.cos(phase),
                             np.sin(phase)])
        coef, *_ = np.linalg.lstsq(regress, self._errors, rcond=None)
        return coef[:taps].T


    def result(self) -> np.ndarray:
        """Identified secondary paths S (C, C, L): error i per command j, per tap (m/s^2/N).

        Raises:
            RuntimeError: if the run is not finished.
        """
        if not self.done:
            raise RuntimeError(f'identification not finished ({100 * self.progress:.0f} %)')
        return self._paths.copy()


class FilteredXLMSController:
    """Multichannel filtered-x LMS (multiple-error LMS) with a sum-of-tones reference.

    Args:
        secondary_paths: (I, J, L) FIR models of the secondary paths (m/s^2 per N per tap),
            error i per command j, L in [32, 128].
        tone_frequencies_hz: reference tones (Hz), in (0, fs/2), no duplicates.
        sample_rate_hz: sample rate fs (Hz).
        mu: normalised step size (dimensionless, >= 0); see the module docstring.
        n_taps: control-filter length N (taps) per actuator.
        reference_amplitudes: amplitude A_t of each tone in the reference (default 1).
        leakage: weight leakage per sample (0 = classic FxLMS), in [0, 1).
    """

    def __init__(
        self,
        secondary_paths: np.ndarray,
        tone_frequencies_hz: Sequence[float] | np.ndarray,
        sample_rate_hz: float,
        mu: float = DEFAULT_FXLMS_MU,
        n_taps: int = DEFAULT_CONTROL_TAPS,
        reference_amplitudes: Sequence[float] | np.ndarray | None = None,
        leakage: float = 0.0,
    ) -> None:
        """Validate the arguments (ValueError) and allocate the ring buffers."""
        s = np.array(secondary_paths, dtype=float)
        if s.ndim != 3 or not np.all(np.isfinite(s)):
            raise ValueError(f'secondary_paths must be a finite (I, J, L) array, got {s.shape}')
        lo, hi = PATH_TAPS_RANGE
        if not lo <= s.shape[2] <= hi:
            raise ValueError(f'secondary-path length L must be in [{lo}, {hi}], got {s.shape[2]}')
        self._fs = float(sample_rate_hz)
        if not np.isfinite(self._fs) or self._fs <= 0.0:
            raise ValueError(f'sample_rate_hz must be finite and > 0, got {sample_rate_hz!r}')
        freqs = validate_frequencies(tone_frequencies_hz, self._fs)
        if freqs.size == 0:
            raise ValueError('at least one tone frequency is required')
        self._freqs = freqs
        self._mu = validate_mu(mu)
        self._n_taps = _check_positive_int('n_taps', n_taps)
        amps = np.ones(freqs.size) if reference_amplitudes is None else np.asarray(
            reference_amplitudes, dtype=float).reshape(-1)
        if amps.shape != freqs.shape or not np.all(np.isfinite(amps)):
            raise ValueError(f'reference_amplitudes must be finite with shape {freqs.shape}')
        if not 0.0 <= leakage < 1.0:
            raise ValueError(f'leakage must be in [0, 1), got {leakage!r}')
        self._ni, self._nj, self._nl = s.shape
        self._paths = s
        self._paths_2d = np.ascontiguousarray(s.reshape(self._ni * self._nj, self._nl))
        self._amps = amps
        self._keep = 1.0 - float(leakage)
        self._dphi = TWO_PI * freqs / self._fs
        self._phi = np.zeros(freqs.size)
        self._cos = np.zeros(freqs.size)
        # Double-length ring buffers: the newest sample is written at pos and pos + M, so
        # buf[pos:pos + M] is always [newest, ..., oldest] without copying.
        self._xlen = max(self._nl, self._n_taps)
        self._xbuf = np.zeros(2 * self._xlen)
        self._xpos = 0
        self._rbuf = np.zeros((2 * self._n_taps, self._ni, self._nj))
        self._rbuf_2d = self._rbuf.reshape(2 * self._n_taps, self._ni * self._nj)
        self._rpos = 0
        self._r = np.zeros(self._ni * self._nj)
        self._w = np.zeros((self._n_taps, self._nj))
        self._grad = np.zeros((self._n_taps, self._nj))
        self._u = np.zeros(self._nj)
        self._enabled = True
        self._frozen = False
        # adaptation waits until the filtered-reference window holds real data (L + N - 1
        # samples), otherwise the normalisation by a partly empty window gives huge steps
        self._warmup = self._nl + self._n_taps - 1

    # ------------------------------------------------------------------ hot path
    def step(self, error: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Adapt on the error of sample n and return the command of sample n.

        Args:
            error: e_n, (I,) accelerations (m/s^2) of sample n, DC removed.
            out: optional (J,) float array to write the command into (no allocation).

        Returns:
            u_n, (J,) command forces (N) for sample n (``out`` if given, else a new array).
            Zero while disabled (the reference and filtered reference keep running).
            Adaptation starts once L + N - 1 samples have filled the filtered-reference
            window.
        """
        e = np.asarray(error, dtype=float)
        if e.shape != (self._ni,):
            raise ValueError(f'error must have shape ({self._ni},), got {e.shape}')
        # reference x_n and its history
        np.cos(self._phi, out=self._cos)
        x = float(np.dot(self._amps, self._cos))
        m = self._xlen
        self._xpos = (self._xpos - 1) % m
        self._xbuf[self._xpos] = x
        self._xbuf[self._xpos + m] = x
        xhist = self._xbuf[self._xpos:self._xpos + m]
        # filtered reference r_ij[n] = S_ij * x, pushed into its history
        np.dot(self._paths_2d, xhist[:self._nl], out=self._r)
        n = self._n_taps
        self._rpos = (self._rpos - 1) % n
        self._rbuf_2d[self._rpos] = self._r
        self._rbuf_2d[self._rpos + n] = self._r
        if self._warmup > 0:
            self._warmup -= 1
        elif self._enabled and not self._frozen and self._mu > 0.0:
            self._adapt(e)
        if self._enabled:
            np.dot(xhist[:n], self._w, out=self._u)
        else:
            self._u[:] = 0.0
        self._phi += self._dphi
        np.remainder(self._phi, TWO_PI, out=self._phi)
        if out is None:
            return self._u.copy()
        out[...] = self._u
        return out

    def _adapt(self, e: np.ndarray) -> None:
        """W[k, j] -= mu / (eps + ||R||^2) sum_i e_i r_ij[n - k]."""
        n = self._n_taps
        hist = self._rbuf[self._rpos:self._rpos + n]               # (N, I, J), newest first
        flat = self._rbuf_2d[self._rpos:self._rpos + n]
        power = float(np.vdot(flat, flat))
        np.matmul(e, hist, out=self._grad)                        # (N, J)
        self._grad *= self._mu / (NORMALISATION_EPS + power)
        if self._keep != 1.0:
            self._w *= self._keep
        self._w -= self._grad

    # ------------------------------------------------------------------ configuration
    def set_enabled(self, flag: bool) -> None:
        """Enable (adapt and drive) or disable (zero output, weights kept) the controller."""
        self._enabled = bool(flag)

    def set_frozen(self, flag: bool) -> None:
        """Freeze (True) or resume (False) adaptation; the output keeps running."""
        self._frozen = bool(flag)

    def set_mu(self, mu: float) -> None:
        """Set the normalised step size (>= 0, finite); ValueError keeps the old one."""
        self._mu = validate_mu(mu)

    def reset_weights(self) -> None:
        """Set every control-filter weight to zero."""
        self._w[:] = 0.0

    # ------------------------------------------------------------------ read-only views
    @property
    def weights(self) -> np.ndarray:
        """Control filters W (N, J): tap k of actuator j (N per unit reference), a copy."""
        return self._w.copy()

    @property
    def secondary_paths(self) -> np.ndarray:
        """Secondary-path models S (I, J, L), a copy."""
        return self._paths.copy()

    @property
    def tone_frequencies_hz(self) -> np.ndarray:
        """Reference tones (Hz), a copy."""
        return self._freqs.copy()

    @property
    def mu(self) -> float:
        """Normalised step size."""
        return self._mu

    @property
    def enabled(self) -> bool:
        """Whether the controller adapts and drives its output."""
        return self._enabled

    def equivalent_tone_weights(self) -> np.ndarray:
        """Complex (T, J) command phasors (N) the filters produce at each tone.

        ``u_j = Re{sum_t A_t W_j(w_t) e^{j phi_t}}``, ``W_j(w) = sum_k W[k, j] e^{-j w k}``:
        the notch's weight convention, for comparing the two controllers' solutions.
        """
        k = np.arange(self._n_taps)
        kernel = np.exp(-1j * self._dphi[:, None] * k[None, :])
        return self._amps[:, None] * (kernel @ self._w)


def multiply_adds_per_sample(n_err: int, n_act: int, path_taps: int, control_taps: int,
                             n_tones: int) -> int:
    """Multiply-adds per sample of :class:`FilteredXLMSController` (analytic count).

    Filtered reference I*J*L, normalisation I*J*N, gradient I*J*N, update J*N, output J*N,
    reference T.
    """
    ij = n_err * n_act
    return ij * path_taps + 2 * ij * control_taps + 2 * n_act * control_taps + n_tones


# ---------------------------------------------------------------------- core closed loop
class FxlmsCoreLoop(CoreLoop):
    """:class:`~hexapod_vibration.core.closed_loop.CoreLoop` with FxLMS in place of the notch.

    Same plant, DC blocker, pointing loop, actuator limits and timeline: at
    ``scenario.identify_at_s`` the secondary paths are identified
    (:class:`SecondaryPathIdentifier`, the scenario's controller tones removed as
    nuisance), then the controller runs disabled (reference and filtered reference
    running) and is enabled at ``scenario.control_on_s``. The identification must end
    before the uncontrolled analysis window (``control_on_s - window_s``).
    ``LoopRecord.notch_command_n`` holds the FxLMS command and ``plant_response`` the
    identified FIR models' response at the tones (T, C, C); ``weights`` stays zero.

    Args:
        config: physical model.
        scenario: scenario (its ``notch`` section gives the tones; its ``mu`` is not used).
        mu: FxLMS normalised step size.
        path_taps: secondary-path FIR length L.
        control_taps: control-filter length N.
        id_amplitude_n: identification excitation level (N).
        id_settle_s: identification settle time per actuator (s).
        id_measure_s: identification fitted time per actuator (s).
    """

    def __init__(self, config: ModelConfig, scenario: Scenario, mu: float = DEFAULT_FXLMS_MU,
                 path_taps: int = DEFAULT_PATH_TAPS, control_taps: int = DEFAULT_CONTROL_TAPS,
                 id_amplitude_n: float = 2.0, id_settle_s: float = 0.1,
                 id_measure_s: float = 0.7) -> None:
        """Build plant and loops as CoreLoop does; the FxLMS is created after identification."""
        super().__init__(config, scenario)
        self.notch = None                    # the notch of the base class is not used
        tones = scenario.notch.tone_frequencies_hz
        if not tones:
            raise ValueError('the scenario has no controller tones (notch.tone_frequencies_hz)')
        self.tones_hz = tuple(tones)
        self.mu = validate_mu(mu)
        self.path_taps = int(path_taps)
        self.control_taps = int(control_taps)
        self._id_args = dict(n_taps=self.path_taps, amplitude_n=id_amplitude_n,
                             settle_s=id_settle_s, measure_s=id_measure_s,
                             nuisance_frequencies_hz=self.tones_hz, seed=scenario.seed)
        id_s = STRUTS * (id_settle_s + id_measure_s)
        if scenario.identify_at_s + id_s > scenario.control_on_s - scenario.window_s + 1e-9:
            raise ValueError(
                f'FxLMS identification ({id_s:g} s from {scenario.identify_at_s:g} s) would '
                f'overlap the uncontrolled window starting at '
                f'{scenario.control_on_s - scenario.window_s:g} s')
        self.path_identifier: SecondaryPathIdentifier | None = None
        self.fxlms: FilteredXLMSController | None = None
        self.secondary_paths: np.ndarray | None = None

    def _notch_step(self, n: int, error: np.ndarray, record: LoopRecord) -> np.ndarray:
        if n == int(round(self.scenario.identify_at_s * self.fs)):
            self.path_identifier = SecondaryPathIdentifier(STRUTS, self.fs, **self._id_args)
        if self.path_identifier is not None:
            command = self.path_identifier.step(error)
            if self.path_identifier.done:
                self._install_controller(record)
            return command
        if self.fxlms is None:
            return np.zeros(STRUTS)
        if n == record.control_on_sample:
            self.fxlms.set_enabled(True)
        return self.fxlms.step(error)

    def _install_controller(self, record: LoopRecord) -> None:
        self.secondary_paths = self.path_identifier.result()
        self.path_identifier = None
        self.fxlms = FilteredXLMSController(self.secondary_paths, self.tones_hz, self.fs,
                                            mu=self.mu, n_taps=self.control_taps)
        self.fxlms.set_enabled(False)
        record.plant_response = fir_frequency_response(self.secondary_paths, self.tones_hz,
                                                       self.fs)
        record.notes.append(f'FxLMS: {STRUTS}x{STRUTS} secondary paths, L={self.path_taps} '
                            f'taps, N={self.control_taps} control taps, mu={self.mu:g}')
