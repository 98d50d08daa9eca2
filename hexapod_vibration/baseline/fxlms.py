"""Multichannel filtered-x LMS (Elliott's multiple-error LMS): the model-based baseline.

The paper compares its Adaptive Notch Canceller with the classic model-based alternative,
the multiple-error LMS of Elliott, Stothers and Nelson (1987). This module implements its
tonal, multiple-reference form with the same prior knowledge and the same step interface
as :class:`~hexapod_vibration.core.control.notch.AdaptiveNotchCanceller`, so that both run in the
same loop and their cost per sample can be compared:

- References ``x_k[n] = a_k cos(phi_k,n)``: one sinusoid per disturbance tone k (known
  frequencies, as for the notch), with its own control filters and filtered references. A
  single summed reference would let any other tone in the error (e.g. an uncontrolled
  harmonic) mix into every filter through the products of the LMS gradient.
- Secondary paths ``S[i, j, l]`` (m/s^2 per N): FIR impulse responses (``L`` taps, 32-128)
  from command ``j`` to error ``i``, identified on the running plant before control
  (:class:`SecondaryPathIdentifier`), with the pairing of docs/architecture.md:
  ``e_i[n] = sum_j sum_l S[i, j, l] u_j[n - l] + d_i[n]`` (so ``S[:, :, 0]`` is ~0).
- Control filters ``W[m, k, j]`` (N per unit reference): one FIR of ``N`` taps per tone
  and actuator, ``u_j[n] = sum_k sum_m W[m, k, j] x_k[n - m]``.
- Filtered references ``r_kij[n] = sum_l S[i, j, l] x_k[n - l]`` and the normalised update
  ``W[m, k, j] -= mu * sum_i e_i[n] r_kij[n - m]``, where the reference amplitude ``a_k``
  makes the filtered-reference power of each tone in the filters' window one (normalised
  LMS per tone: ``mu`` is dimensionless, stable for small ``mu``).

Cost per sample: ``K*I*J*L`` multiply-adds for the filtered references (the model's cost,
which grows with the plant order through ``L``), ``K*I*J*N`` for the gradient and
``2*K*J*N`` for the update and the output (:func:`multiply_adds_per_sample`), against
O(K*C) for the notch whatever the plant.

:class:`FxlmsCoreLoop` runs a scenario of :mod:`hexapod_vibration.core.sim.closed_loop` with this
controller in place of the notch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexapod_vibration.core.control.adaptation import SampledRun
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.notch import TWO_PI, validate_frequencies
from hexapod_vibration.core.control.notch_weights import validate_mu
from hexapod_vibration.core.control.phasor import PhasorBank
from hexapod_vibration.core.model.config import ModelConfig
from hexapod_vibration.core.sim.closed_loop import STRUTS, CoreLoop, LoopRecord
from hexapod_vibration.core.sim.scenario import Scenario

DEFAULT_PATH_TAPS = 64
DEFAULT_CONTROL_TAPS = 32
PATH_TAPS_RANGE = (32, 128)
DEFAULT_FXLMS_MU = 0.05
NORMALISATION_EPS = 1e-12
# rows between two block copies of the sliding histories (samples)
HISTORY_BLOCK = 256


def _check_positive_int(name: str, value: int) -> int:
    v = int(value)
    if v != value or v < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return v


def fir_frequency_response(paths: np.ndarray, freqs_hz: Sequence[float] | np.ndarray,
                           sample_rate_hz: float) -> np.ndarray:
    """Complex response G[t, i, j] = sum_l S[i, j, l] e^{-j w_t l} of FIR paths.

    This is the phasor of error ``i`` per unit phasor of command ``j`` in the convention of
    docs/architecture.md, directly comparable with
    :class:`~hexapod_vibration.core.control.adaptation.ToneResponseIdentifier`.

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
    return np.einsum("ijl,tl->tij", s, kernel)


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
        self._c = _check_positive_int("n_channels", n_channels)
        self._fs = float(sample_rate_hz)
        if not np.isfinite(self._fs) or self._fs <= 0.0:
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {sample_rate_hz!r}")
        self._taps = _check_positive_int("n_taps", n_taps)
        lo, hi = PATH_TAPS_RANGE
        if not lo <= self._taps <= hi:
            raise ValueError(f"n_taps must be in [{lo}, {hi}], got {n_taps}")
        if not np.isfinite(amplitude_n) or amplitude_n <= 0.0:
            raise ValueError(f"amplitude_n must be finite and > 0, got {amplitude_n!r}")
        self._nuisance = validate_frequencies(nuisance_frequencies_hz, self._fs)
        self._settle = int(round(settle_s * self._fs))
        self._measure = int(round(measure_s * self._fs))
        n_par = self._taps + 1 + 2 * self._nuisance.size
        if self._settle < 0 or self._measure < 4 * n_par:
            raise ValueError(f"settle_s must be >= 0 and measure_s must hold >= 4 x {n_par} "
                             f"samples (L + 1 + 2T parameters), got {self._measure}")
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
            raise RuntimeError(f"identification not finished ({100 * self.progress:.0f} %)")
        return self._paths.copy()


class _SlidingHistories:
    """Newest-first windows over the recent rows of several signals, no copy per sample.

    Row ``n`` of every signal is written at position ``p`` of its buffer of
    ``depth + block`` rows and ``p`` moves down by one per sample, so ``buf[p:p + depth]``
    is always ``[newest, ..., oldest]``. When ``p`` would leave the buffers, the newest
    ``depth - 1`` rows of each are moved to its end (one block copy every ``block + 1``
    samples) and ``p`` restarts at ``block``. The buffers start as zeros (a zero past).

    Args:
        shapes: per signal, (window depth in rows, shape of one row).
        block: rows between two block copies.
    """

    def __init__(self, shapes: Sequence[tuple[int, tuple[int, ...]]],
                 block: int = HISTORY_BLOCK) -> None:
        """Allocate the zeroed buffers; the first :meth:`push` returns ``block``."""
        self.block = block
        self.depths = [depth for depth, _ in shapes]
        self.buffers = [np.zeros((depth + block, *row)) for depth, row in shapes]
        self.pos = block + 1

    def push(self) -> int:
        """Move every buffer to the next row position and return it (caller writes it)."""
        p = self.pos - 1
        if p < 0:
            for depth, buf in zip(self.depths, self.buffers, strict=True):
                buf[self.block + 1:] = buf[:depth - 1]
            p = self.block
        self.pos = p
        return p


class FilteredXLMSController:
    """Multichannel multiple-reference filtered-x LMS, one reference per tone.

    The tonal form of Elliott's multiple-error LMS: every tone k has its own sinusoidal
    reference ``x_k[n] = a_k cos(phi_k,n)``, its own control filters and its own filtered
    references. Per sample (I errors, J actuators, K tones, L model taps, N control taps):

    - filtered references ``r_kij[n] = sum_l S[i, j, l] x_k[n - l]`` (K*I*J*L multiply-adds),
    - normalised update ``W[m, k, j] -= mu * sum_i e_i[n] r_kij[n - m]`` (K*I*J*N),
    - output ``u_j[n] = sum_k sum_m W[m, k, j] x_k[n - m]`` (K*J*N).

    Normalisation: the reference amplitude ``a_k = (eps + N/2 ||S(w_k)||_F^2)^(-1/2)`` makes
    the filtered-reference power of tone k in the filters' N-tap window one, so the plain
    LMS step above is the normalised LMS step ``mu / ||R_k||^2`` of each tone (the tones are
    orthogonal, so every tone adapts at the rate ``mu`` sets, whatever the plant gain at
    its frequency). For a sinusoidal reference of known amplitude this power is known from
    the model, so it costs nothing per sample. ``mu`` is dimensionless.

    Args:
        secondary_paths: (I, J, L) FIR models of the secondary paths (m/s^2 per N per tap),
            error i per command j, L in PATH_TAPS_RANGE.
        tone_frequencies_hz: reference tones (Hz), in (0, fs/2), no duplicates.
        sample_rate_hz: sample rate fs (Hz).
        mu: normalised step size (dimensionless, >= 0).
        n_taps: control-filter length N (taps) per tone and actuator.
        leakage: weight leakage per sample (0 = classic FxLMS), in [0, 1).
    """

    def __init__(
        self,
        secondary_paths: np.ndarray,
        tone_frequencies_hz: Sequence[float] | np.ndarray,
        sample_rate_hz: float,
        mu: float = DEFAULT_FXLMS_MU,
        n_taps: int = DEFAULT_CONTROL_TAPS,
        leakage: float = 0.0,
    ) -> None:
        """Validate the arguments (ValueError) and allocate the histories."""
        s = _validate_paths(secondary_paths)
        self._fs = float(sample_rate_hz)
        if not np.isfinite(self._fs) or self._fs <= 0.0:
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {sample_rate_hz!r}")
        freqs = validate_frequencies(tone_frequencies_hz, self._fs)
        if freqs.size == 0:
            raise ValueError("at least one tone frequency is required")
        self._freqs = freqs
        self._mu = validate_mu(mu)
        self._n_taps = _check_positive_int("n_taps", n_taps)
        if not 0.0 <= leakage < 1.0:
            raise ValueError(f"leakage must be in [0, 1), got {leakage!r}")
        self._keep = 1.0 - float(leakage)
        self._ni, self._nj, self._nl = s.shape
        self._paths = s
        self._dphi = TWO_PI * freqs / self._fs
        self._osc = PhasorBank(self._dphi, amplitudes=self._normalising_amplitudes())
        self._enabled = True
        self._frozen = False
        self._allocate()

    def _normalising_amplitudes(self) -> np.ndarray:
        """a_k (K,): unit filtered-reference power per tone in the N-tap window."""
        g = fir_frequency_response(self._paths, self._freqs, self._fs)      # (K, I, J)
        power = 0.5 * self._n_taps * np.sum(np.abs(g) ** 2, axis=(1, 2))
        return 1.0 / np.sqrt(NORMALISATION_EPS + power)

    def _allocate(self) -> None:
        """Histories, weights and the views the hot path uses at each buffer position."""
        k, i, j, ell, n = self._freqs.size, self._ni, self._nj, self._nl, self._n_taps
        # paths as (L, J*I): filtered references come out as (K, J, I), so the gradient
        # sum_i e_i r_kij[n - m] is one matrix-vector product over every (m, k, j)
        self._paths_t = np.ascontiguousarray(self._paths.transpose(2, 1, 0).reshape(ell, j * i))
        self._hist = _SlidingHistories([(max(ell, n), (k,)), (n, (k, j, i))])
        xb, rb = self._hist.buffers
        positions = range(self._hist.block + 1)
        self._x_slot = [xb[p] for p in positions]
        self._x_model = [xb[p:p + ell].T for p in positions]                 # (K, L)
        self._x_filter = [xb[p:p + n].reshape(n * k) for p in positions]     # (N*K,)
        self._r_slot = [rb[p].reshape(k, j * i) for p in positions]          # (K, J*I)
        self._r_window = [rb[p:p + n].reshape(n * k * j, i) for p in positions]
        self._w = np.zeros((n, k, j))
        self._w_flat = self._w.reshape(-1)
        self._w_2d = self._w.reshape(n * k, j)
        self._grad = np.zeros(n * k * j)
        self._e_mu = np.zeros(i)
        self._mu_vec = np.full(i, self._mu)          # (a vector multiplies faster than a float)
        self._u = np.zeros(j)
        self._z_re = self._osc.z.real
        # adaptation waits until the filtered-reference window holds real data (L + N - 1
        # samples): before, the filtered references come from a partly empty history
        self._warmup = ell + n - 1

    # ------------------------------------------------------------------ hot path
    def step(self, error: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Adapt on the error of sample n and return the command of sample n.

        Args:
            error: e_n, (I,) accelerations (m/s^2) of sample n, DC removed.
            out: optional (J,) float array to write the command into (no allocation).

        Returns:
            u_n, (J,) command forces (N) for sample n (``out`` if given, else a new array).
            Zero while disabled (the references and filtered references keep running).
            Adaptation starts once L + N - 1 samples have filled the filtered-reference
            window.
        """
        e = np.asarray(error, dtype=float)
        if e.shape != (self._ni,):
            raise ValueError(f"error must have shape ({self._ni},), got {e.shape}")
        p = self._hist.push()
        np.copyto(self._x_slot[p], self._z_re)                              # x_k[n]
        np.dot(self._x_model[p], self._paths_t, out=self._r_slot[p])        # r_kji[n]
        if self._warmup > 0:
            self._warmup -= 1
        elif self._enabled and not self._frozen and self._mu > 0.0:
            self._adapt(e, p)
        if self._enabled:
            np.dot(self._x_filter[p], self._w_2d, out=self._u)
        else:
            self._u[:] = 0.0
        self._osc.rotate()
        if out is None:
            return self._u.copy()
        out[...] = self._u
        return out

    def _adapt(self, e: np.ndarray, p: int) -> None:
        """W[m, k, j] -= mu sum_i e_i r_kij[n - m] (normalised by the references' amplitude)."""
        np.multiply(e, self._mu_vec, out=self._e_mu)
        np.dot(self._r_window[p], self._e_mu, out=self._grad)
        if self._keep != 1.0:
            self._w_flat *= self._keep
        np.subtract(self._w_flat, self._grad, out=self._w_flat)

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
        self._mu_vec[:] = self._mu

    def reset_weights(self) -> None:
        """Set every control-filter weight to zero."""
        self._w[:] = 0.0

    # ------------------------------------------------------------------ read-only views
    @property
    def weights(self) -> np.ndarray:
        """Control filters W (N, K, J): tap m of tone k's filter for actuator j, a copy.

        Units: N per unit of the internal reference ``x_k`` (amplitude
        :attr:`reference_amplitudes`).
        """
        return self._w.copy()

    @property
    def reference_amplitudes(self) -> np.ndarray:
        """Internal reference amplitudes a_k (K,) (normalisation, see the class), a copy."""
        return self._osc.amplitudes

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

    @property
    def n_taps(self) -> int:
        """Control-filter length N (taps)."""
        return self._n_taps

    def equivalent_tone_weights(self) -> np.ndarray:
        """Complex (K, J) command phasors (N) the filters produce at each tone.

        ``u_j = Re{sum_k U[k, j] e^{j phi_k}}`` with ``U[k, j] = a_k sum_m W[m, k, j]
        e^{-j w_k m}``: the notch's weight convention, for comparing the two controllers.
        """
        m = np.arange(self._n_taps)
        kernel = np.exp(-1j * self._dphi[:, None] * m[None, :])                 # (K, N)
        return self._osc.amplitudes[:, None] * np.einsum("km,mkj->kj", kernel, self._w)


def _validate_paths(secondary_paths: np.ndarray) -> np.ndarray:
    """Return the (I, J, L) secondary paths as a float array or raise ValueError."""
    s = np.array(secondary_paths, dtype=float)
    if s.ndim != 3 or not np.all(np.isfinite(s)):
        raise ValueError(f"secondary_paths must be a finite (I, J, L) array, got {s.shape}")
    lo, hi = PATH_TAPS_RANGE
    if not lo <= s.shape[2] <= hi:
        raise ValueError(f"secondary-path length L must be in [{lo}, {hi}], got {s.shape[2]}")
    return s


def multiply_adds_per_sample(n_err: int, n_act: int, path_taps: int, control_taps: int,
                             n_tones: int, leakage: bool = False) -> int:
    """Real multiply-adds per sample of :class:`FilteredXLMSController` (analytic count).

    References 4 per tone (one complex phasor rotation), filtered references K*I*J*L,
    step-size scaling of the error I, gradient K*I*J*N, update K*J*N (twice with leakage),
    output K*J*N. The normalisation is a constant of the model: nothing per sample.
    """
    kij = n_tones * n_err * n_act
    kjn = n_tones * n_act * control_taps
    return (4 * n_tones + kij * path_taps + n_err + kij * control_taps
            + (3 if leakage else 2) * kjn)


# ---------------------------------------------------------------------- core closed loop
class FxlmsCoreLoop(CoreLoop):
    """:class:`~hexapod_vibration.core.sim.closed_loop.CoreLoop` with FxLMS in place of the notch.

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
        self.dc_blocker = DCBlocker(STRUTS, self.fs)
        tones = scenario.notch.tone_frequencies_hz
        if not tones:
            raise ValueError("the scenario has no controller tones (notch.tone_frequencies_hz)")
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
                f"FxLMS identification ({id_s:g} s from {scenario.identify_at_s:g} s) would "
                f"overlap the uncontrolled window starting at "
                f"{scenario.control_on_s - scenario.window_s:g} s")
        self.path_identifier: SecondaryPathIdentifier | None = None
        self.fxlms: FilteredXLMSController | None = None
        self.secondary_paths: np.ndarray | None = None

    def _controller_step(self, n: int, accel_m_s2: np.ndarray,
                         record: LoopRecord) -> np.ndarray:
        """The FxLMS command (N) for sample ``n`` from the raw accelerations (m/s^2)."""
        error = self.dc_blocker.step(accel_m_s2)
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
        record.notes.append(f"FxLMS: {STRUTS}x{STRUTS} secondary paths, L={self.path_taps} "
                            f"taps, one reference per tone ({len(self.tones_hz)}), "
                            f"N={self.control_taps} control taps, mu={self.mu:g}")
