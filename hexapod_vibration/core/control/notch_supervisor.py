"""The whole notch controller, without ROS: canceller, identification, bounds and sequencing.

:class:`NotchSupervisor` is what the ``notch_controller`` node runs and what the core
closed loop (:mod:`hexapod_vibration.core.sim.closed_loop`) runs, so that both take exactly
the same steps. Per sample it removes the DC from the raw accelerations (m/s^2), steps the
Adaptive Notch Canceller (:mod:`~hexapod_vibration.core.control.notch`) and, when one is
running, the plant identification at the tones, and returns the command (N). Between
samples it takes parameter changes as a checked set: :meth:`NotchSupervisor.check` refuses
a set with the reason and changes nothing, :meth:`NotchSupervisor.apply` applies a set that
passed (the node's on-set and post-set parameter callbacks).

Sequencing (the paper leaves "finding the adaptation rate coefficient" to the user; here
the supervisor finds it):
- the normalised adaptation modes (``decentralized``, ``centralized``) wait for an
  identification of the plant at their tones, started ``identify_delay_s`` after the
  first sample (``auto_identify``), on request, or when tones or the mode change; the
  canceller is frozen meanwhile and its output stays as it was;
- the identification gives ``G`` (T, C, C), the coefficients ``P`` and the stability bound
  on ``mu`` (eq. 18 with the loop delay, the minimum over the tones); a ``mu`` at or above
  the bound is lowered to half of it at once; a bound of 0 (no stable rate) keeps control
  off;
- ``raw`` (the paper as printed, ``P = I``) adapts from the first sample; its
  identification only measures G and the bound (and freezes the weights meanwhile).
- ``identification: broadband`` measures G(f) over 0..fs/2 instead (10 s multisine,
  :class:`~hexapod_vibration.core.control.plant_identification.BroadbandIdentifier`,
  off-grid disturbance lines fitted and removed): G at the tones comes from it, the bound
  is the Nyquist limit on G(f) (eq. 18 is 15-50x optimistic on the PPH), ``mu_policy``
  folds its per-tone rates into P and :attr:`NotchSupervisor.sensitivity` holds the
  predicted |S(f)| before control goes on;
- every identification carries a confidence figure (1 - its relative uncertainty at the
  tones: the broadband lines' standard error and interpolation error, or how far the
  disturbance moved between the tone identification's two baselines); above 10 % (G(f))
  or 25 % (baselines) control is refused (state ``refused``, the reason in ``refusal``);
- the divergence guard (:mod:`~hexapod_vibration.core.control.divergence_guard`) records
  the error's band levels while control is off and nothing is injected, and under control
  lowers ``mu``, then fades out, when a band rises above that level; the
  canceller clamps its weights to ``weight_limit_n`` after every update (anti-windup);
- with the tones fixed (no tracking, no tachometer), the line under each tone is located
  from the weights' turning (:mod:`~hexapod_vibration.core.control.line_offset`); a line
  where the prediction gives control less than ``guard_margin_db`` of reduction (a
  mismatch or a drift beyond the notch's width) fades control out before any band rises.

Moving tones (``frequency_tracking``, ``reference_harmonics``): the phase-locked tracker
pulls a tone in only from about the canceller's own bandwidth, so the tones are first
*acquired*: after a broadband identification at the strongest disturbance line it fitted
within each tone's tracking bounds (P from G(f) there), and again when adaptation starts at
the strongest line of the last second of error without output (a drifting line has moved
since); the tracker then fine-tracks. The guard's tone bands follow the oscillators (its
reference is kept). A stale tachometer leaves the tones where it had them (tracking goes
on from there); reported in the events and ``status()`` (``acquired_hz``, ``guard_bands``,
``reference``). A sweeping tone (the reference's slope or the tracker's learnt rate above
:data:`SWEEP_RATE_FLOOR_HZ_PER_S`) adapts with a type-2 update (the weights' rate of change
integrated too, :data:`MOVING_TONE_DAMPING`) that follows the disturbance's change as the
tone moves through the plant's response; steady tones keep the paper's update.

Missing samples (a gap in the indices) move the phases on as if the samples had been
there (:meth:`AdaptiveNotchCanceller.advance`); a gap during an identification restarts it.

What the supervisor decides and the node must tell (log lines, a ``mu`` it lowered that
the ROS parameter must mirror) is queued as :class:`SupervisorEvent` for
:meth:`NotchSupervisor.drain_events`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Generator, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod_vibration.contract import SAMPLE_RATE_HZ, STRUT_COUNT, NotchState
from hexapod_vibration.core.control import adaptation, mu_policy, sensitivity
from hexapod_vibration.core.control.divergence_guard import (
    FADE_S,
    GUARD_BACKED_OFF,
    GUARD_DISABLED,
    GUARD_OFF,
    GUARD_REFERENCING,
    GUARD_WATCHING,
    MU_DIVISOR,
    DivergenceGuard,
    GuardVerdict,
)
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.frequency_tracker import (
    ACQUISITION_RECORD_S,
    DEFAULT_BLOCK_SAMPLES,
    SETTLE_TIME_CONSTANTS,
    FrequencyTracker,
    acquisition_frequencies,
    combine_orders,
    loop_bandwidths_hz,
    strongest_lines_hz,
    weight_phase_error,
)
from hexapod_vibration.core.control.line_offset import MIN_COHERENCE, LineOffsetMonitor
from hexapod_vibration.core.control.mu_policy import DEFAULT_MAX_RISE_DB
from hexapod_vibration.core.control.notch import (
    AdaptiveNotchCanceller,
    validate_frequencies,
    validate_mu,
    validate_update_lowpass,
)
from hexapod_vibration.core.control.plant_identification import (
    BroadbandIdentifier,
    DisturbanceSpectrum,
    PlantFrequencyResponse,
    RemovedLine,
)

MAX_TONES = 16
"""Largest number of tones the controller accepts (oscillators, harmonics included)."""
MAX_HARMONICS = MAX_TONES - 1
"""Largest ``harmonics`` setting (orders 2..16 of one tone; tones x orders <= MAX_TONES)."""
LINE_OFFSET_FADE_S = 5.0
"""Fade (s) of the output when a line is off the notch (nothing runs away there), after
:data:`LINE_OFFSET_MU_RAMP_S`. (Measured on ``drift`` when the weights froze at once, core
loop against its twin, the quiet 44.7-56.2 Hz third octave, worst 1 s block during the
fade: +3.9 dB with 2 s, +3.0 with 3 s, +1.3 with 5 s.)"""
LINE_OFFSET_MU_RAMP_S = 2.0
"""Before that fade, mu falls to 0 over this (s, raised cosine) with the weights still
adapting; then they freeze. Weights that follow a line off the notch turn at the offset:
frozen at once they stop turning and the output's frequency jumps back to the oscillator's
(a kink of its phase, a 1/df^2 skirt). Until 2026-12-03 each oscillator was moved to where
its weights had turned over the last 50 ms, which held for one steadily turning line
(``drift``) but not for weights that wander: ``spin_up`` without tracking froze orders 2
and 3 (0.09 and 0.03 N, 2-5 Hz off their lines) onto 60.69 and 95.22 Hz, and the kink put
+11 dB into the quiet 44.7-56.2 Hz band. With mu falling the weights slow down and shrink
smoothly (for a line off the notch, ``|W|`` scales with mu). Core loop against the twin,
worst 12 s window from control-on (Welch 4 s): ``spin_up`` without tracking +2.50 ->
+0.44 dB, ``drift`` +0.63 -> +0.35 dB (a 1 s fall, prototype: +0.41 / +0.29 dB; over 1 s
blocks ``drift`` is +5.2 dB in 44.7-56.2 Hz while mu falls, +4.6 dB in 56-71 Hz before)."""
MU_RAMP_STEP_SAMPLES = 10
"""The falling mu is set every this many samples (each setting rescales P: a few array
operations)."""
DETECTOR_RAMP_TIME_CONSTANTS = 1.0
"""After the settling, the phase detector's gain rises linearly to 1 over this many
adaptation time constants (1/mu samples)."""
ACQUISITION_SLOPE_WINDOW_HZ = 1.0
"""The halves of the acquisition record look for the line within this of where the whole
record found it (Hz): its rate of change is their difference."""
P_RETUNE_HZ = 0.05
"""A moved oscillator's coefficients are checked against the broadband G(f) after this
shift (Hz)."""
P_RETUNE_CHANGE = 0.1
"""...and replaced only when some tone's P would change by this fraction of its norm (about
6 degrees of phase): a tone drifting +-1 Hz at 40 Hz then keeps its P (each replacement
kicks the phase detector: third octave 56-71 Hz +1.15 dB over the uncontrolled twin at a
P every 0.05 Hz, +0.59 dB with this), one sweeping 30 -> 150 Hz gets a new P every few
tenths of a hertz (``spin_up`` unchanged, within 0.3 dB per order)."""
MOVING_TONE_DAMPING = 0.7
"""Damping ratio of the type-2 weight update that moving tones (tracking or a reference)
adapt with (:meth:`AdaptiveNotchCanceller.set_integral_ratio`, ratio ``1 / (4 zeta^2)``).

A tone sweeping at a steady rate changes the disturbance it cancels (its path's response at
the tone's frequency, an amplitude growing with speed^2): the first-order update lags that
by its time constant, ``1/mu`` samples, and leaves the change over one time constant as the
residual. ``spin_up`` (core loop, tachometer, mu 0.006): the residual equals
``tau dD/dt`` (correlation 0.98-1.00); order 2 through the disturbance path's zero near 90
Hz changes by 24 %/s (z axis: a deeper minimum) and kept only 21 dB, order 3 at 93 Hz
18 dB (the identified G(f) is within 0.1 % of the model's there and -P G / 2 = I: neither
P nor the rate is the cause). The rate integrator removes the steady part of the change:
ramp (17-36 s) minimum 21 -> 41 dB on order 2 and 20 -> 33 dB on order 3 with the
tachometer, 21 -> 36 and 19 -> 30 dB tracked; 0.7 beat 1.0 and 1.5 on the averaged loop
driven by the recorded disturbance (order 3: 44, 35, 26 dB)."""
MOVING_TONE_INTEGRAL_RATIO = 1.0 / (4.0 * MOVING_TONE_DAMPING ** 2)
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
(:meth:`_ToneFollowing._follow_sweep_rate`)."""
REFERENCE_STATES = ("unused", "waiting", "following", "stale")
IDENTIFICATION_METHODS = ("tones", "broadband")
MAX_IDENTIFICATION_UNCERTAINTY = 0.1
"""An identification whose relative uncertainty at a tone exceeds this is refused (10 %:
a gain within 10 % and a phase within ~6 degrees)."""
MAX_BASELINE_CHANGE = 0.25
"""The tone identification is refused when the disturbance at a tone moved by more than
this fraction of the response between its two baselines (0.4 Hz off the tone: 48 %; a plant
still settling 0.2 s after start-up: 12 %, whose G is still within 3 %)."""
GUARD_SETTLE_S = 0.5
"""After the first sample (DC blocker) and after an identification (the excitation's
decay) the guard waits this long before the error counts as the level without control (s)."""
DEFAULT_WEIGHT_LIMIT_N = 40.0
"""The model's strut dynamic force limit (config/pph_model.yaml force_limit_dynamic_n)."""
DEFAULT_UPDATE_LOWPASS_HZ = 0.0
"""Default corner of the update low-pass (Hz): 0, the paper's update."""


@dataclass(frozen=True)
class NotchConfig:
    """Settings of the notch controller; the field names are the node's ROS parameters.

    Attributes:
        mu: normalised adaptation rate (1/sample): the weights converge as (1 - mu)^n.
        tone_frequencies_hz: tones to cancel (Hz), each in (0, fs/2), distinct, at most 16.
        enabled: control output on (ramped over ``ramp_s``); while off the weights are kept.
        adaptation: ``decentralized`` (six SISO loops, the paper), ``centralized``
            (P = -2 G^-1) or ``raw`` (P = I, mu not normalised).
        auto_identify: identify at start-up and whenever the tones or the mode change.
        identify_delay_s: wait after the first sample before the start-up identification (s).
        identification_amplitude_n: test-tone amplitude per tone (N peak).
        identification_settle_s: discarded settling time per identification segment (s).
        identification_measure_s: fitted time per identification segment (s).
        dc_cutoff_hz: corner of the DC blocker before the canceller (Hz).
        loop_delay_samples: loop delay used in the stability bound (samples).
        ramp_s: enable/disable fade time (s).
        frequency_tracking: estimate each tone's frequency online and let the
            canceller's oscillators follow it (issue 11).
        tracking_range_hz: largest deviation of a tracked tone from its nominal (Hz).
        reference_harmonics: one order per tone (may be non-integer): tone k follows
            order_k x the reference frequency (tachometer, Hz) while it arrives; empty:
            no reference.
        reference_timeout_s: a reference older than this is stale: the tones hold where
            the reference had them and, with ``frequency_tracking``, track from there (s).
        harmonics: also cancel orders 2..harmonics+1 of every tone, following it.
        mu_policy: ``manual`` (every tone at ``mu``, a warning when the predicted rise
            exceeds ``max_rise_db``) or ``auto`` (per tone the largest rate within it).
        max_rise_db: the largest predicted rise of the vibration off the tones (dB).
        divergence_guard: watch every controlled band against its level before control
            and back off (lower mu, then fade out) when control makes it
            worse (:mod:`~hexapod_vibration.core.control.divergence_guard`).
        guard_margin_db: rise over the level before control that counts as worse (dB).
        weight_limit_n: anti-windup: each strut's weights never add up to more than this
            (N), the actuator's dynamic rating.
        identification: ``tones`` (test tones at the tones, 3.2 s with one or two tones;
            eq. 18 bound) or ``broadband`` (a 10 s multisine over 0..fs/2 that survives a
            disturbance a fraction of a hertz from a tone; the Nyquist bound on the
            identified G(f), the mu policy and the predicted sensitivity).
        update_lowpass_hz: corner of the low-pass on each tone's weight correction (Hz;
            0: the paper's update): the canceller's gain far from its tones falls by
            ``update_lowpass_hz / |f - f_t|`` more, so its tails no longer lift a lightly
            damped loop mode (never worse than off at the paper's rates); in the bound
            and the prediction. Set at start-up.
    """

    mu: float = 0.002
    tone_frequencies_hz: tuple[float, ...] = (40.0, 80.0)
    enabled: bool = True
    adaptation: str = "decentralized"
    auto_identify: bool = True
    identify_delay_s: float = 1.0
    identification_amplitude_n: float = 2.0
    identification_settle_s: float = 0.1
    identification_measure_s: float = 0.3
    dc_cutoff_hz: float = 0.5
    loop_delay_samples: float = 2.0
    ramp_s: float = 0.05
    frequency_tracking: bool = False
    tracking_range_hz: float = 2.0
    reference_harmonics: tuple[float, ...] = ()
    reference_timeout_s: float = 0.1
    harmonics: int = 0
    mu_policy: str = "manual"
    max_rise_db: float = DEFAULT_MAX_RISE_DB
    divergence_guard: bool = True
    guard_margin_db: float = 1.0
    weight_limit_n: float = DEFAULT_WEIGHT_LIMIT_N
    identification: str = "tones"
    update_lowpass_hz: float = DEFAULT_UPDATE_LOWPASS_HZ

    def replaced(self, changes: Mapping[str, Any]) -> NotchConfig:
        """A copy with ``changes`` (parameter name -> value); unknown names raise KeyError."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise KeyError(f"not a notch setting: {', '.join(sorted(unknown))}")
        values = dict(changes)
        for name in ("tone_frequencies_hz", "reference_harmonics"):
            if name in values:
                values[name] = tuple(float(f) for f in values[name] or ())
        return dataclasses.replace(self, **values)


@dataclass(frozen=True)
class SupervisorEvent:
    """Something the supervisor did that the node reports.

    Attributes:
        level: ``info``, ``warn`` or ``error`` (the log level).
        message: one line for the log.
        parameter: (name, value) of a setting the supervisor changed itself (a lowered
            ``mu``), for the node to mirror into its ROS parameter; None otherwise.
    """

    level: str
    message: str
    parameter: tuple[str, Any] | None = None


@dataclass
class _MuFall:
    """A line-offset fade under way: mu falling to 0 before the weights freeze."""

    mu: float
    """mu when the fall started (restored if control is tried again)."""
    samples: int
    """Length of the fall (samples)."""
    fade_samples: int
    """The output's fade once the weights froze (samples)."""
    done: int = 0
    """Samples of the fall so far."""
    last_mu: float = float("nan")
    """The last mu the fall set: another one in force means someone else set it."""


@dataclass(frozen=True)
class _Plan:
    """A checked set of changes: resulting tones, mode, known response, P and bound."""

    tones: list[float]
    mode: str
    response: np.ndarray | None
    coefficients: np.ndarray | None
    bound: float


def _tone_key(frequency_hz: float) -> float:
    return round(float(frequency_hz), 6)


def bank_frequencies(tones_hz: np.ndarray | list[float], harmonics: int) -> np.ndarray:
    """Every oscillator's frequency (Hz): orders 1..harmonics+1 of each tone, order-major.

    Row ``k * T + t`` of the bank is order ``k + 1`` of tone ``t`` (T tones).
    """
    tones = np.asarray(tones_hz, dtype=float).reshape(-1)
    orders = np.arange(1, int(harmonics) + 2, dtype=float)
    return (orders[:, None] * tones[None, :]).reshape(-1)


def coefficients_and_bound(response: np.ndarray, mode: str,
                           delay_samples: float) -> tuple[np.ndarray, float]:
    """Adaptation coefficients P (T, C, C) for ``mode`` and the bound on ``mu``.

    The bound is eq. 18 with the loop delay (:func:`adaptation.mu_bound`) at every tone,
    the smallest over the tones: the rate must be stable at all of them.

    Args:
        response: identified plant response G (T, C, C), (m/s^2)/N.
        mode: one of :data:`adaptation.COEFFICIENT_MODES`.
        delay_samples: loop delay beyond the one-sample command hold (samples).

    Raises:
        ValueError: G unusable for ``mode`` (ill-conditioned, zero diagonal, not finite).
    """
    coefficients = adaptation.normalized_coefficients(response, mode)
    bound = min(adaptation.mu_bound(g, c, delay_samples)
                for g, c in zip(response, coefficients, strict=True))
    return coefficients, float(bound)


class NotchSupervisor:
    """The notch controller: raw accelerations in, strut commands out, one call per sample.

    Args:
        config: initial settings (checked as a whole; ValueError with the reason).
        sample_rate_hz: loop rate fs (Hz).
        channels: number of struts C.
        output_weights: c (C,): the output whose rise ``mu_policy`` bounds and the
            prediction reports, ``c^T e`` (e.g. the top plate's z axis, the z row of
            ``J^-1``, what the report measures); None: the 6x6 loop's largest singular
            value (any disturbance direction).
    """

    def __init__(self, config: NotchConfig, sample_rate_hz: float = SAMPLE_RATE_HZ,
                 channels: int = STRUT_COUNT,
                 output_weights: np.ndarray | None = None) -> None:
        """Build the canceller and the DC blocker; identification waits for the first sample."""
        self.fs = float(sample_rate_hz)
        self.channels = int(channels)
        self.output_weights = (None if output_weights is None
                               else np.asarray(output_weights, dtype=float))
        self._config = config
        self._follow = _ToneFollowing(self)
        tones = bank_frequencies(config.tone_frequencies_hz, config.harmonics).tolist()
        raw = config.adaptation == "raw"
        # Raw (paper as printed, P = I) adapts at once; the normalised modes wait for the
        # identification to give them their coefficients.
        self.canceller = AdaptiveNotchCanceller(self.channels, tones if raw else [], self.fs,
                                                validate_mu(config.mu))
        if not raw:
            self.canceller.set_tone_frequencies(tones, ramp_samples=0)
        self.canceller.set_enabled(False, ramp_samples=0)
        self.canceller.set_weight_limit(config.weight_limit_n)
        self.canceller.set_update_lowpass(config.update_lowpass_hz)
        self.dc_blocker = DCBlocker(self.channels, self.fs, config.dc_cutoff_hz)
        self._command = np.zeros(self.channels)
        self.identifier: adaptation.ToneResponseIdentifier | None = None
        self.plant_response: np.ndarray | None = None
        self.identified_tones: list[float] = []
        self._responses: dict[float, np.ndarray] = {}
        self.bound = self._normalised_bound()
        self.last_sample = -1
        self.first_sample = -1
        self.enabled_since_sample = -1
        self.identification_start_sample = -1
        self.identification_end_sample = -1
        self.refusal = ""
        self.counters = {"gaps": 0, "missed_samples": 0, "duplicates": 0}
        self.weight_clamps = 0
        self._events: list[SupervisorEvent] = []
        self._identifying_tones: list[float] = []
        self._analysis: Iterator[None] | None = None
        self.plant_frequency_response: PlantFrequencyResponse | None = None
        self.disturbance_spectrum: DisturbanceSpectrum | None = None
        self.sensitivity: sensitivity.SensitivityPrediction | None = None
        self.mu_choice: mu_policy.MuChoice | None = None
        self.mu_limit = float("nan")
        self.identification_confidence = float("nan")
        self.guard = DivergenceGuard(self.channels, self.fs, tones, config.guard_margin_db)
        self.guard_action = ""
        self.line_monitor = LineOffsetMonitor(len(tones), self.fs)
        self._mu_fall: _MuFall | None = None
        self._lines_hz = np.zeros(0)
        self._guard_backed_off = False
        self._guard_gave_up = False
        self._quiet_from_sample = -1
        self._last_clamp_event = -10**9
        self.bound = self._plan({"mu": config.mu,
                                 "tone_frequencies_hz": list(config.tone_frequencies_hz),
                                 "adaptation": config.adaptation,
                                 "harmonics": config.harmonics}).bound
        self._follow.rebuild()
        if raw or not config.auto_identify:
            self.canceller.set_enabled(config.enabled, ramp_samples=0)

    # ------------------------------------------------------------------ settings
    @property
    def config(self) -> NotchConfig:
        """The settings in force."""
        return self._config

    @property
    def ramp_samples(self) -> int:
        """Fade length (samples) for enable/disable and removed tones."""
        return int(round(self._config.ramp_s * self.fs))

    def check(self, changes: Mapping[str, Any]) -> None:
        """Check a set of changes (parameter name -> value) as a whole; change nothing.

        Raises:
            ValueError: the reason the set is refused (for the caller, one line).
        """
        self._plan(changes)

    def apply(self, changes: Mapping[str, Any]) -> None:
        """Apply a set of changes that :meth:`check` accepted.

        Raises:
            ValueError: the set is refused (nothing changed), as :meth:`check` would say.
        """
        plan = self._plan(changes)
        old = self._config
        self._config = old.replaced(changes)
        # The node mirrors a mu the supervisor lowered into its ROS parameter, which comes
        # back here: only a different mu is the user's new choice.
        new_mu = "mu" in changes and float(changes["mu"]) != self.canceller.mu
        if "mu" in changes:
            self.canceller.set_mu(changes["mu"])
        tones_changed = "tone_frequencies_hz" in changes or "harmonics" in changes
        mode_changed = "adaptation" in changes
        if "weight_limit_n" in changes:
            self.canceller.set_weight_limit(float(changes["weight_limit_n"]))
        if "guard_margin_db" in changes:
            self.guard.margin_db = float(changes["guard_margin_db"])
        if tones_changed:
            self.guard.set_tones(plan.tones)
        if tones_changed or mode_changed or new_mu:
            self._clear_guard_refusal()
        if tones_changed:
            self.canceller.set_tone_frequencies(plan.tones, coefficients=plan.coefficients,
                                                ramp_samples=self.ramp_samples)
        elif mode_changed and plan.coefficients is not None:
            self.canceller.set_coefficients(plan.coefficients)
        self.plant_response, self.bound = plan.response, plan.bound
        self.identified_tones = plan.tones if plan.response is not None else []
        if "enabled" in changes:
            self._set_enabled(bool(changes["enabled"]))
        if tones_changed or mode_changed:
            self._after_tone_or_mode_change(plan, mode_changed)
        if tones_changed or any(name in changes for name in _FOLLOW_SETTINGS):
            self._follow.rebuild()

    def _clear_guard_refusal(self) -> None:
        """New settings: the guard's fade-out no longer holds; control may try again."""
        if not self._guard_gave_up:
            return
        self._guard_restart()
        self.refusal = ""
        if (self.identifier is None and self._analysis is None
                and self.plant_response is not None):
            self.canceller.set_frozen(False)
            self.canceller.set_enabled(self._config.enabled, self.ramp_samples)

    def _check_tones(self, changes: Mapping[str, Any]) -> None:
        if "tone_frequencies_hz" not in changes:
            return
        tones = list(changes["tone_frequencies_hz"] or [])
        if len(tones) > MAX_TONES:
            raise ValueError(f"at most {MAX_TONES} tones, got {len(tones)}")
        try:
            validate_frequencies(tones, self.fs)
        except ValueError as exc:
            raise ValueError(f"tone_frequencies_hz rejected: {exc}") from None

    def _bank_for(self, changes: Mapping[str, Any]) -> list[float]:
        """The oscillators (Hz) of the settings after ``changes``; ValueError if refused.

        Checks the tracking, reference and harmonics settings together with the tones:
        at most :data:`MAX_TONES` oscillators, every order below fs/2 over the whole
        tracking range, one reference order per tone.
        """
        try:
            cfg = self._config.replaced(changes)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"rejected: {exc}") from None
        tones = np.asarray(cfg.tone_frequencies_hz, dtype=float)
        harmonics = cfg.harmonics
        if (isinstance(harmonics, bool) or int(harmonics) != harmonics
                or not 0 <= harmonics <= MAX_HARMONICS):
            raise ValueError(f"harmonics must be an integer in 0..{MAX_HARMONICS}, "
                             f"got {harmonics!r}")
        orders = int(harmonics) + 1
        if tones.size * orders > MAX_TONES:
            raise ValueError(f"{tones.size} tones x {orders} orders (harmonics={harmonics}) "
                             f"= {tones.size * orders} oscillators: at most {MAX_TONES}")
        span = float(cfg.tracking_range_hz)
        if not np.isfinite(span) or span < 0.0:
            raise ValueError(f"tracking_range_hz must be finite and >= 0, got {span}")
        reach = tones + (span if cfg.frequency_tracking else 0.0)
        if tones.size and orders * reach.max() >= 0.5 * self.fs:
            raise ValueError(f"order {orders} of {tones[np.argmax(reach)]:g} Hz (tracked up "
                             f"to {reach.max():g} Hz) reaches fs/2 = {0.5 * self.fs:g} Hz")
        ref = np.asarray(cfg.reference_harmonics, dtype=float)
        if ref.size and ref.size != tones.size:
            raise ValueError(f"reference_harmonics needs one order per tone ({tones.size}), "
                             f"got {ref.size}")
        if ref.size and not np.all(np.isfinite(ref) & (ref > 0.0)):
            raise ValueError(f"reference_harmonics must be finite and > 0, got {ref.tolist()}")
        timeout = float(cfg.reference_timeout_s)
        if not np.isfinite(timeout) or timeout <= 0.0:
            raise ValueError(f"reference_timeout_s must be finite and > 0, got {timeout}")
        bank = bank_frequencies(tones, harmonics)
        try:
            validate_frequencies(bank, self.fs)
        except ValueError as exc:
            raise ValueError(f"harmonics={harmonics} rejected: {exc}") from None
        return bank.tolist()

    @staticmethod
    def _check_guard_settings(changes: Mapping[str, Any]) -> None:
        """Refuse bad identification, policy, guard and weight-limit settings."""
        method = changes.get("identification", IDENTIFICATION_METHODS[0])
        if method not in IDENTIFICATION_METHODS:
            raise ValueError(f"identification must be one of {IDENTIFICATION_METHODS}, "
                             f"got {method!r}")
        if "mu_policy" in changes or "max_rise_db" in changes:
            mu_policy.validate_policy(changes.get("mu_policy", "manual"),
                                      changes.get("max_rise_db", DEFAULT_MAX_RISE_DB))
        for name in ("weight_limit_n", "guard_margin_db"):
            value = changes.get(name, 1.0)
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")

    def _check_start_up_settings(self, changes: Mapping[str, Any]) -> None:
        """Refuse a change of a setting that is fixed at start-up (the bound depends on it)."""
        if ("update_lowpass_hz" in changes
                and float(changes["update_lowpass_hz"]) != self._config.update_lowpass_hz):
            validate_update_lowpass(changes["update_lowpass_hz"], self.fs)
            raise ValueError("update_lowpass_hz is set at start-up (the stability bound and "
                             "the prediction were computed with "
                             f"{self._config.update_lowpass_hz:g} Hz)")

    def _plan(self, changes: Mapping[str, Any]) -> _Plan:
        """Check a set of changes as a whole, changing nothing.

        The stability bound is that of the resulting mode and tone set (the identified
        plant at those tones, else the normalised bound), so a change of ``adaptation`` or
        of the tones is refused too if it would leave the present ``mu`` unstable.
        ``mu = 0`` (no adaptation) is always stable.

        Raises:
            ValueError: the reason to refuse the changes.
        """
        self._check_tones(changes)
        self._check_guard_settings(changes)
        self._check_start_up_settings(changes)
        tones = self._bank_for(changes)
        mode = changes.get("adaptation", self._config.adaptation)
        if mode not in adaptation.COEFFICIENT_MODES:
            raise ValueError(f"adaptation must be one of {adaptation.COEFFICIENT_MODES}, "
                             f"got {mode!r}")
        if any(k in changes for k in ("tone_frequencies_hz", "adaptation", "harmonics")):
            response = self._known_response(tones)
            try:
                coefficients, bound = self._coefficients_for(tones, response, mode)
            except ValueError as exc:
                raise ValueError(f"adaptation={mode!r} rejected: {exc}") from None
        else:
            response, coefficients, bound = self.plant_response, None, self.bound
        mu = changes.get("mu", self.canceller.mu)
        if not np.isfinite(mu) or mu < 0.0:
            raise ValueError(f"mu must be finite and >= 0, got {mu}")
        if mu > 0.0 and mu >= bound and any(k in changes for k in (
                "mu", "adaptation", "tone_frequencies_hz", "harmonics")):
            raise ValueError(f"mu={mu:g} is outside the stability bound {bound:.4g} ({mode} "
                             f"adaptation at {tones} Hz, eq. 18 with a "
                             f"{self._config.loop_delay_samples:g}-sample loop delay)")
        return _Plan(tones, mode, response, coefficients, bound)

    def _after_tone_or_mode_change(self, plan: _Plan, mode_changed: bool) -> None:
        """Identify what the new tone set or mode needs; drop an identification it does not."""
        if plan.response is not None or plan.mode == "raw" or not plan.tones:
            if self.identifier is not None:    # nothing to measure any more: bumpless stop
                self._event("info", "identification no longer needed: stopped")
                self.identifier = None
                self.canceller.set_frozen(False)
                self.canceller.set_enabled(self._config.enabled, self.ramp_samples)
            return
        if mode_changed:      # a normalised mode must not adapt with another mode's P
            self.canceller.set_frozen(True)
        running = self.identifier is not None and np.array_equal(
            self._identifying_tones, plan.tones)
        if self._config.auto_identify and self.first_sample >= 0 and not running:
            self.start_identification(plan.tones)

    def _set_enabled(self, flag: bool) -> None:
        if self.identifier is None and self._analysis is None and not (flag and self.refusal):
            self.canceller.set_enabled(flag, self.ramp_samples)
        self.enabled_since_sample = self.last_sample + 1 if flag else -1
        self._event("info", f"control {'on' if flag else 'off'} from sample "
                            f"{self.last_sample + 1}")

    # ------------------------------------------------------------------ identification
    def _normalised_bound(self) -> float:
        return adaptation.delayed_mode_mu_bound(1.0, self._config.loop_delay_samples)

    def _known_response(self, tones: list[float]) -> np.ndarray | None:
        """Identified G (T, C, C) at ``tones``, or None if a tone was never identified."""
        if self.plant_frequency_response is not None and tones:
            return self.plant_frequency_response.at(tones)
        rows = [self._responses.get(_tone_key(f)) for f in tones]
        if not rows or any(r is None for r in rows):
            return None
        return np.stack(rows)

    def _coefficients_for(self, tones: list[float], response: np.ndarray | None,
                          mode: str) -> tuple[np.ndarray | None, float]:
        """Coefficients for the canceller (None: new tones wait) and the mu bound."""
        if response is not None and self.plant_frequency_response is not None:
            coefficients = adaptation.normalized_coefficients(response, mode)
            return coefficients, self._nyquist_limit(tones, coefficients)
        if response is not None:
            return coefficients_and_bound(response, mode, self._config.loop_delay_samples)
        if mode == "raw":
            identity = np.broadcast_to(np.eye(self.channels, dtype=complex),
                                       (len(tones), self.channels, self.channels))
            return (identity.copy() if tones else None), np.inf
        return None, self._normalised_bound()

    def start_identification(self, tones: list[float] | None = None) -> str:
        """Begin measuring G at the tones from the next sample on; the canceller is frozen.

        Args:
            tones: tones to identify (Hz); None: the canceller's tones.

        Returns:
            A one-line description of the run.

        Raises:
            ValueError: there are no tones to identify.
        """
        return self._start_identification(tones, self.last_sample + 1)

    def _start_identification(self, tones: list[float] | None, first_sample: int) -> str:
        """Start an identification whose first sample is ``first_sample``."""
        tones = [float(f) for f in (tones if tones is not None
                                    else self.canceller.tone_frequencies_hz)]
        if not tones:
            raise ValueError("no tones to identify")
        cfg = self._config
        if cfg.identification == "broadband":
            self.identifier = BroadbandIdentifier(self.channels, self.fs)
            what = "over 0..fs/2 (multisine)"
        else:
            self.identifier = adaptation.ToneResponseIdentifier(
                self.channels, tones, self.fs, cfg.identification_amplitude_n,
                cfg.identification_settle_s, cfg.identification_measure_s)
            what = f"at {tones} Hz"
        self._identifying_tones = tones
        self.canceller.set_frozen(True)
        self.identification_start_sample = first_sample
        self.identification_end_sample = -1
        text = f"identifying the plant {what} ({self.identifier.duration_s:.1f} s of samples)"
        self._event("info", text)
        return text

    def _nyquist_limit(self, tones: list[float], coefficients: np.ndarray) -> float:
        """Largest common rate the Nyquist test finds stable on the identified G(f)."""
        return sensitivity.stable_mu_limit(self.plant_frequency_response.at, tones, self.fs,
                                           coefficients,
                                           update_lowpass_hz=self._config.update_lowpass_hz)

    def _measured_response(self) -> tuple[np.ndarray, float, float, str]:
        """G at the tones from the finished identifier, its uncertainty, limit, what it is."""
        tones = self._identifying_tones
        if isinstance(self.identifier, BroadbandIdentifier):
            pfr = self.identifier.result()
            self.plant_frequency_response = pfr
            self.disturbance_spectrum = self.identifier.disturbance()
            uncertainty = float(np.max(pfr.uncertainty_at(tones)))
            return (pfr.at(tones), uncertainty, MAX_IDENTIFICATION_UNCERTAINTY,
                    "relative uncertainty of G(f) at the tones")
        response = self.identifier.result()
        self.plant_frequency_response = None
        self.disturbance_spectrum = None
        change = self.identifier.baseline_change()
        for f, g in zip(tones, response, strict=True):
            self._responses[_tone_key(f)] = g
        return response, float(np.max(change)), MAX_BASELINE_CHANGE, (
            "change of the disturbance at the tones during the identification")

    def _finish_identification(self) -> Iterator[None]:
        """The analysis of a finished identification, one piece per sample (a generator).

        G, its confidence, the coefficients, the bound, the policy and the prediction: with
        a broadband G(f) the Nyquist tests of the bound take ~0.1 s each, so :meth:`step`
        runs one per sample (the lockstep driver waits at most ``lockstep_timeout_s`` for
        a sample's command). The canceller stays frozen and off meanwhile (state
        ``identifying``).
        """
        response, uncertainty, limit, what = self._measured_response()
        identifier, self.identifier = self.identifier, None
        self.identification_end_sample = self.last_sample
        self._quiet_from_sample = self.last_sample + int(round(GUARD_SETTLE_S * self.fs))
        self.identification_confidence = float(max(0.0, 1.0 - uncertainty))
        self.sensitivity = self.mu_choice = None
        if self.plant_frequency_response is not None:
            yield                          # the tone identification's analysis is quick
        tones = [float(f) for f in self.canceller.tone_frequencies_hz]
        mode = self._config.adaptation
        if uncertainty > limit:
            self.plant_response, self.identified_tones = None, []
            self._refuse(f"identification failed: {what} {100 * uncertainty:.0f} % > "
                         f"{100 * limit:.0f} % (a disturbance "
                         "next to a tone?); control stays off")
            return
        broadband = isinstance(identifier, BroadbandIdentifier)
        lines = identifier.disturbance_lines() if broadband else []    # an FFT of the record
        self._lines_hz = np.array([line.frequency_hz for line in lines])
        if (self._follow.tracker is not None and broadband
                and self._follow.reference_state != "following"):
            self._follow.acquire(lines)
            tones = [float(f) for f in self.canceller.tone_frequencies_hz]
        current = response if tones == self._identifying_tones else self._known_response(
            tones)
        try:
            if current is None:
                raise ValueError(f"no identified response at {tones} Hz")
            if self.plant_frequency_response is not None:
                coefficients = adaptation.normalized_coefficients(current, mode)
            else:
                coefficients, bound = self._coefficients_for(tones, current, mode)
        except ValueError as exc:
            self._refuse(f"identification unusable for {mode}: {exc}; not adapting")
            return
        if self.plant_frequency_response is not None:
            bound = yield from self._mu_limit_steps(tones, coefficients)
        self.plant_response, self.identified_tones, self.bound = current, tones, bound
        self.mu_limit = bound
        self.canceller.set_coefficients(coefficients)
        gains = np.abs(np.diagonal(current, axis1=1, axis2=2)).mean(axis=1)
        source = "Nyquist on G(f)" if self.plant_frequency_response is not None else "eq. 18"
        self._event("info", f"identified: |G_ii| {np.round(gains, 4)} (m/s^2)/N, confidence "
                            f"{self.identification_confidence:.3f}, mu bound {bound:.4g} "
                            f"({source})")
        if bound <= 0.0:
            self._clamp_mu(0.0)
            self._refuse(f"identified mu bound is 0 ({mode} adaptation at {tones} Hz): no "
                         "stable rate, control stays off")
            return
        self.refusal = ""
        self._clamp_mu(bound)
        if self.plant_frequency_response is not None:
            yield
            self._apply_mu_policy(tones, coefficients)
        self.canceller.set_frozen(False)
        self._guard_restart()
        self.canceller.set_enabled(self._config.enabled, self.ramp_samples)
        if self._config.enabled and self.enabled_since_sample < 0:
            self.enabled_since_sample = self.last_sample + 1

    def _mu_limit_steps(self, tones: list[float], coefficients: np.ndarray
                        ) -> Generator[None, None, float]:
        """The Nyquist limit on G(f), one stability test per ``yield`` (a generator).

        As :func:`~hexapod_vibration.core.control.sensitivity.stable_mu_limit` (the
        largest stable common rate), found by doubling from 1e-5 and bisecting to 2 %;
        moving tones with the type-2 update they sweep with (:attr:`integral_ratio_setting`).
        """
        cfg = self._config

        def stable(mu: float) -> bool:
            return sensitivity.closed_loop_is_stable(self.plant_frequency_response.at,
                                                     tones, self.fs, coefficients, mu,
                                                     integral_ratio=self.integral_ratio_setting,
                                                     update_lowpass_hz=cfg.update_lowpass_hz)

        lo = 1e-5
        if not stable(lo):
            return 0.0
        hi = lo
        while True:
            yield
            hi = min(2.0 * hi, 1.0)
            if not stable(hi):
                break
            lo = hi
            if hi >= 1.0:
                return 1.0
        while hi > lo * 1.02:
            yield
            mid = float(np.sqrt(lo * hi))
            lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        return lo

    def _apply_mu_policy(self, tones: list[float], coefficients: np.ndarray) -> None:
        """Per-tone rates of ``mu_policy`` folded into P; the predicted sensitivity."""
        cfg, mu = self._config, self.canceller.mu
        pfr, phi = self.plant_frequency_response, self.disturbance_spectrum
        choice = mu_policy.choose_tone_rates(pfr.at, tones, self.fs, coefficients, mu,
                                             policy=cfg.mu_policy,
                                             max_rise_db=cfg.max_rise_db,
                                             output_weights=self.output_weights,
                                             disturbance_csd=phi.at,
                                             update_lowpass_hz=cfg.update_lowpass_hz)
        self.mu_choice = choice
        folded = sensitivity.per_tone_coefficients(coefficients, mu, choice.tone_mu)
        self.canceller.set_coefficients(folded)
        self.sensitivity = sensitivity.predict_sensitivity(
            pfr.at, tones, self.fs, folded, mu, output_weights=self.output_weights,
            disturbance_csd=phi.at, check_stability=False,
            update_lowpass_hz=cfg.update_lowpass_hz)
        self._event("warn" if choice.warning else "info",
                    choice.warning or f"mu_policy {choice.policy}: tone rates "
                    f"{np.round(choice.tone_mu, 6).tolist()}, predicted rise "
                    f"{choice.predicted_rise_db:.2f} dB at {choice.rise_at_hz:.2f} Hz")

    def _refuse(self, reason: str) -> None:
        """Keep control off (frozen, faded out) and say why."""
        self.refusal = reason
        self.canceller.set_frozen(True)
        self.canceller.set_enabled(False, self.ramp_samples)
        self._event("error", reason)

    def _clamp_mu(self, bound: float) -> None:
        """Lower ``mu`` to half the bound (0 for a bound of 0) if it is not below it."""
        mu = self.canceller.mu
        if mu < bound or mu == 0.0:
            return
        clamped = 0.5 * bound
        self.canceller.set_mu(clamped)
        self._config = self._config.replaced({"mu": clamped})
        self._event("warn", f"mu={mu:g} is outside the identified stability bound "
                            f"{bound:.4g}: clamped to {clamped:.4g}", ("mu", clamped))

    # ------------------------------------------------------------------ loop
    def reset_run(self, first_index: int) -> None:
        """A new run of the loop starts at ``first_index`` (a restarted driver).

        The sample sequence restarts there and the DC blocker forgets the old run's
        accelerations; the identified plant, the coefficients and the weights are kept (the
        plant is the same); an identification that was running starts again.
        """
        self.last_sample = int(first_index) - 1
        self.dc_blocker.reset()
        if self._config.enabled and not self.refusal:
            self.enabled_since_sample = int(first_index)
        self._event("warn", f"new run of the loop from sample {first_index}: sequence "
                            "restarted, identification and weights kept")
        if self.identifier is not None:
            self._start_identification(list(self._identifying_tones), int(first_index))

    def step(self, index: int | None, accel_m_s2: np.ndarray) -> np.ndarray | None:
        """Take the raw accelerations of sample ``index``; the command (N) for that sample.

        Args:
            index: the loop's sample index (None: the one after the last one taken).
            accel_m_s2: (C,) raw accelerations, gravity included (m/s^2), finite.

        Returns:
            (C,) command forces (N), a buffer reused by the next call; None if the sample
            is not after the last one taken (a duplicate or out of order: not used).
        """
        index = self.last_sample + 1 if index is None else int(index)
        if index <= self.last_sample:
            self.counters["duplicates"] += 1
            return None
        self._catch_up(index)
        error = self.dc_blocker.step(accel_m_s2)
        clamped = self.canceller.clamped_samples
        command = self.canceller.step(error, out=self._command)
        if self.canceller.clamped_samples != clamped:
            self._weights_clamped()
        if self._config.divergence_guard:
            self._guard_step(error)
        if self._mu_fall is not None and self._mu_fall.done < self._mu_fall.samples:
            self._mu_fall_step()
        if self._follow.active:
            self._follow.step(index, error)
        if self.identifier is not None:
            command += self.identifier.step(error)
            if self.identifier.done:
                self._analysis = self._finish_identification()
                self._advance_analysis()
        elif self._analysis is not None:
            self._advance_analysis()
        return command

    def _advance_analysis(self) -> None:
        """One piece of the running identification analysis."""
        try:
            next(self._analysis)
        except StopIteration:
            self._analysis = None

    def _catch_up(self, index: int) -> None:
        """Keep the phase references on the sample grid across missing samples."""
        if self.first_sample < 0:
            self.first_sample = index
        elif index > self.last_sample + 1:
            gap = index - self.last_sample - 1
            self.counters["gaps"] += 1
            self.counters["missed_samples"] += gap
            self.canceller.advance(gap)
            self._event("warn", f"/pph/accel: {gap} samples missing before {index}")
            if self.identifier is not None:
                self._event("warn", "samples missed during identification: restarting it")
                self._start_identification(list(self._identifying_tones), index)
        self.last_sample = index
        delay = int(round(self._config.identify_delay_s * self.fs))
        if (index - self.first_sample == delay and self.plant_response is None
                and self.identifier is None and self._config.auto_identify
                and self.canceller.tone_frequencies_hz.size):
            self._start_identification(None, index)

    # ------------------------------------------------------------------ guard
    def _weights_clamped(self) -> None:
        """Anti-windup took effect (the canceller's limit, ``weight_limit_n``): say so."""
        self.weight_clamps += 1
        if self.last_sample - self._last_clamp_event >= self.fs:      # one line a second
            self._last_clamp_event = self.last_sample
            self._event("warn", f"weights clamped to the actuator rating "
                                f"{self._config.weight_limit_n:g} N (anti-windup)")

    def _guard_step(self, error: np.ndarray) -> None:
        """Feed the guard; act on its verdict (see divergence_guard for the order)."""
        n = self.last_sample
        quiet = (self.identifier is None and n >= self._quiet_from_sample
                 and n - self.first_sample >= GUARD_SETTLE_S * self.fs)
        off = not self.canceller.enabled and self.canceller.output_gain == 0.0
        controlling = (self.canceller.enabled and self.canceller.output_gain == 1.0
                       and not self.canceller.frozen and self.identifier is None
                       and self.plant_response is not None)
        verdict = self.guard.step(error, recording=quiet and off,
                                  judging=controlling and not self._guard_gave_up)
        if verdict is not None and verdict.action is not None:
            self._guard_act(verdict)
        self._line_offset_step(controlling and not self._guard_gave_up)

    def _line_offset_step(self, controlling: bool) -> None:
        """Fixed tones: locate each tone's line from the weights; fade out off the notch.

        The line sits ``offset_hz`` from its tone; the predicted change of the error there
        (the same |S(f)| the mu policy bounds: the output's, else the worst strut's) says
        what control does to it. Less than ``guard_margin_db`` of reduction for a line the
        weights follow steadily (coherence >= MIN_COHERENCE) means the canceller's model
        (the line at the tone) is wrong by more than its notch is wide: control can gain
        at most the margin and a moving line beats against it (``drift``, without this:
        +7 dB in 44.7-56.2 Hz for 0.5 s and the 79 Hz third octave +5.7 dB before the
        guard's band levels saw it), so it fades out, saying where the line is.
        """
        monitor = self.line_monitor
        if not controlling or self._follow.active or self.sensitivity is None:
            if monitor.started:
                monitor.reset()
            return
        if monitor.tones != self.canceller.n_tones:
            self.line_monitor = monitor = LineOffsetMonitor(self.canceller.n_tones, self.fs)
        if not monitor.step_from(self.canceller) or not monitor.ready:
            return
        tones = self.canceller.tone_frequencies_hz
        lines = tones + monitor.offset_hz
        change_db = self.sensitivity.db_at(lines)
        # only a tone with a disturbance line in its band (fitted by the identification):
        # weights driven by broadband noise alone turn too, at about the notch's width,
        # where a fast notch may reduce little (a false fade on the linear-plant test)
        has_line = np.any(np.abs(self._lines_hz[None, :] - tones[:, None])
                          <= self.guard.half_width_hz, axis=1)
        steady = monitor.coherence >= MIN_COHERENCE
        bad = has_line & steady & (change_db > -self._config.guard_margin_db)
        if not np.any(bad):
            return
        k = int(np.flatnonzero(bad)[0])
        self.guard_action = (
            f"tone {tones[k]:g} Hz: its line is at {lines[k]:.2f} Hz (the weights turn at "
            f"{monitor.offset_hz[k]:+.2f} Hz), where control is predicted to change it by "
            f"{change_db[k]:+.1f} dB (less than guard_margin_db "
            f"{self._config.guard_margin_db:g} dB of reduction) at sample {self.last_sample}")
        # frozen at once, weights that turn would kink the output's phase: mu falls first
        self._fade_out(f"line off the notch: {self.guard_action}: control faded out (mu "
                       f"to 0 over {LINE_OFFSET_MU_RAMP_S:g} s, then the output over "
                       f"{LINE_OFFSET_FADE_S:g} s; frequency_tracking follows a line that is "
                       "not where it was told)", LINE_OFFSET_FADE_S, LINE_OFFSET_MU_RAMP_S)

    def _guard_act(self, verdict: GuardVerdict) -> None:
        """Lower mu, or fade out; say what and why."""
        self.guard_action = f"{verdict.text} at sample {self.last_sample}"
        if verdict.action == "lower_mu":
            mu = self.canceller.mu / MU_DIVISOR
            self.canceller.set_mu(mu)
            self._config = self._config.replaced({"mu": mu})
            self._guard_backed_off = True
            self._event("warn", f"divergence guard: {self.guard_action}: mu lowered to "
                                f"{mu:.4g}", ("mu", mu))
            return
        self._fade_out(f"divergence guard: {self.guard_action}: control faded out "
                       "(worse than off at any rate tried)")

    def _fade_out(self, reason: str, fade_s: float = FADE_S, mu_fall_s: float = 0.0) -> None:
        """Freeze the weights and fade the output to 0 over ``fade_s`` (s); say why.

        With ``mu_fall_s`` > 0 (s) and the weights adapting, mu first falls to 0 over that
        time (:meth:`_mu_fall_step`), and the weights freeze only then. Control stays off
        until the settings change or a new identification succeeds.
        """
        self._guard_gave_up = True
        self.refusal = reason
        canceller = self.canceller
        fade = int(round(fade_s * self.fs))
        if (mu_fall_s > 0.0 and canceller.enabled and not canceller.frozen
                and canceller.mu > 0.0):
            self._mu_fall = _MuFall(canceller.mu, max(int(round(mu_fall_s * self.fs)), 1),
                                    fade, last_mu=canceller.mu)
        else:
            canceller.set_frozen(True)
            canceller.set_enabled(False, fade)
        self._event("error", self.refusal)

    def _mu_fall_step(self) -> None:
        """One sample of a mu fall: a raised cosine to 0, then freeze and fade the output."""
        fall = self._mu_fall
        fall.done += 1
        if fall.done % MU_RAMP_STEP_SAMPLES and fall.done < fall.samples:
            return
        x = min(fall.done / fall.samples, 1.0)
        fall.last_mu = fall.mu * 0.5 * (1.0 + float(np.cos(np.pi * x)))
        self.canceller.set_mu(fall.last_mu)
        if fall.done >= fall.samples:
            self.canceller.set_frozen(True)
            self.canceller.set_enabled(False, fall.fade_samples)

    def _end_mu_fall(self) -> None:
        """Forget a mu fall; give mu back unless someone else set one since."""
        fall, self._mu_fall = self._mu_fall, None
        if fall is not None and self.canceller.mu == fall.last_mu:
            self.canceller.set_mu(fall.mu)

    def _guard_restart(self) -> None:
        """New coefficients or settings: the guard's action sequence starts again."""
        self._end_mu_fall()
        self.guard.restart()
        self._guard_backed_off = self._guard_gave_up = False

    @property
    def guard_state(self) -> str:
        """The guard's state: disabled, referencing, watching, backed_off or off."""
        if not self._config.divergence_guard:
            return GUARD_DISABLED
        if self._guard_gave_up:
            return GUARD_OFF
        if self.state != NotchState.ADAPTING:
            return GUARD_REFERENCING
        return GUARD_BACKED_OFF if self._guard_backed_off else GUARD_WATCHING

    # ------------------------------------------------------------------ reporting
    @property
    def state(self) -> str:
        """One of :class:`NotchState`'s names."""
        if self.identifier is not None or self._analysis is not None:
            return NotchState.IDENTIFYING
        if self.refusal:
            return NotchState.REFUSED
        if self.canceller.enabled and self.plant_response is not None:
            return NotchState.ADAPTING
        return NotchState.ENABLED if self.canceller.enabled else NotchState.DISABLED

    def status(self) -> dict[str, Any]:
        """The controller's state as plain values, for ``/diagnostics``."""
        values: dict[str, Any] = {
            "state": self.state, "enabled": self._config.enabled,
            "enabled_since_sample": self.enabled_since_sample,
            "last_sample": self.last_sample, "mu": self.canceller.mu, "mu_bound": self.bound,
            "adaptation": self._config.adaptation,
            "tones_hz": [float(f) for f in self.canceller.tone_frequencies_hz],
            "identified_tones_hz": self.identified_tones,
            "identification_start_sample": self.identification_start_sample,
            "identification_end_sample": self.identification_end_sample,
            **self.counters}
        values.update(self._follow.status())
        if self.refusal:
            values["refusal"] = self.refusal
        values.update(self._guard_status())
        if self.plant_response is not None:
            diag = np.diagonal(self.plant_response, axis1=1, axis2=2)
            values["plant_gain_m_s2_per_n"] = np.round(np.abs(diag).mean(axis=1), 6).tolist()
            values["plant_phase_deg"] = np.round(np.rad2deg(np.angle(diag.mean(axis=1))),
                                                 2).tolist()
        return values

    # ------------------------------------------------------------------ moving tones
    @property
    def integral_ratio_setting(self) -> float:
        """The type-2 ratio for sweeping tones (:data:`MOVING_TONE_INTEGRAL_RATIO`), or 0.

        Non-zero when the tones may move (tracking or a reference); 0: the paper's update.
        """
        cfg = self._config
        moving = bool(cfg.tone_frequencies_hz) and (cfg.frequency_tracking
                                                    or bool(cfg.reference_harmonics))
        return MOVING_TONE_INTEGRAL_RATIO if moving else 0.0

    @property
    def tone_estimates_hz(self) -> np.ndarray:
        """(T,) the frequency (Hz) each configured tone's oscillator runs at now."""
        return self._follow.fundamentals_hz.copy()

    def set_reference_frequency(self, frequency_hz: float, index: int | None = None) -> None:
        """Take a tachometer value (Hz) that belongs to loop sample ``index``.

        With ``reference_harmonics`` set, tone k runs at order_k x the reference while the
        value is at most ``reference_timeout_s`` old; a value that is not finite and > 0 is
        ignored (and reported once). ``index`` None: the last sample taken.
        """
        self._follow.set_reference(frequency_hz, self.last_sample if index is None
                                   else int(index))

    def _guard_status(self) -> dict[str, Any]:
        """The status keys of the identification, the mu policy and the guard."""
        choice = self.mu_choice
        rise, at_hz = ((choice.predicted_rise_db, choice.rise_at_hz) if choice is not None
                       else (float("nan"), float("nan")))
        return {"identification": self._config.identification,
                "identification_confidence": round(self.identification_confidence, 4),
                "mu_limit": self.mu_limit, "mu_policy": self._config.mu_policy,
                "tone_mu": ([] if choice is None
                            else np.round(choice.tone_mu, 8).tolist()),
                "predicted_rise_db": round(float(rise), 3),
                "predicted_rise_at_hz": round(float(at_hz), 3),
                "guard": self.guard_state, "guard_action": self.guard_action,
                "guard_reference_blocks": self.guard.reference_blocks,
                "weight_clamps": self.weight_clamps, **self._line_status()}

    def _line_status(self) -> dict[str, Any]:
        """The lines located under fixed tones (``line_offset_hz``, ``line_coherence``)."""
        monitor = self.line_monitor
        if not monitor.ready:
            return {}
        return {"line_offset_hz": np.round(monitor.offset_hz, 4).tolist(),
                "line_coherence": np.round(monitor.coherence, 3).tolist()}

    def _event(self, level: str, message: str,
               parameter: tuple[str, Any] | None = None) -> None:
        self._events.append(SupervisorEvent(level, message, parameter))

    def drain_events(self) -> list[SupervisorEvent]:
        """The events since the last call, oldest first (and forget them)."""
        events, self._events = self._events, []
        return events


_FOLLOW_SETTINGS = ("frequency_tracking", "tracking_range_hz", "reference_harmonics",
                    "reference_timeout_s", "harmonics", "tone_frequencies_hz")


def _norm_ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T,) ||a_t|| / ||b_t|| of two (T, C, C) stacks (Frobenius; b_t = 0 counts as tiny)."""
    return (np.linalg.norm(a, axis=(1, 2))
            / np.maximum(np.linalg.norm(b, axis=(1, 2)), 1e-300))


class _ToneFollowing:
    """The tone set in force each block: nominal, tracked or reference-driven, + harmonics.

    Every :data:`DEFAULT_BLOCK_SAMPLES` samples (when tracking or a reference is
    configured) the fundamentals are chosen: ``order_k x reference`` while the reference
    is fresh, else the :class:`FrequencyTracker` estimate when ``frequency_tracking`` is
    on, else nominal; the canceller's oscillators (all orders) are retuned to them
    phase-continuously. While the canceller is identifying, the tones hold.
    """

    def __init__(self, supervisor: NotchSupervisor) -> None:
        """Idle until :meth:`rebuild` reads the supervisor's settings."""
        self.sup = supervisor
        self.active = False
        self.block = DEFAULT_BLOCK_SAMPLES
        self.count = 0
        self.fundamentals_hz = np.zeros(0)
        self.acquired_hz = np.zeros(0)
        self.tracker: FrequencyTracker | None = None
        self._record: np.ndarray | None = None
        self._record_n = 0
        self._record_broken = False
        self.reference_hz = float("nan")
        self.reference_index = -1
        self.reference_slope = 0.0             # Hz per sample, from the last two values
        self.reference_state = "unused"
        self._ignoring = False
        self._previous_w: np.ndarray | None = None
        self._p_at_hz: np.ndarray | None = None
        self._detector_source: np.ndarray | None = None
        self._rate_scale = 1.0
        self._adapting_since = -1
        self._detector: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
        self._sweep_hz_per_s: np.ndarray | None = None
        self._integrating_from = -1
        self._blocks = 0                       # blocks retuned (SWEEP_CHECK_BLOCKS)
        self._swept_at: np.ndarray | None = None

    def rebuild(self) -> None:
        """Re-read the settings; the tracker restarts from where the tones are.

        New tones or orders start at nominal; otherwise tracked tones keep their present
        frequencies (within the new bounds) and untracked ones go back to nominal, with
        the oscillators retuned phase-continuously.
        """
        cfg = self.sup.config
        nominal = np.asarray(cfg.tone_frequencies_hz, dtype=float)
        same = (np.array_equal(nominal, getattr(self, "nominal_hz", None))
                and cfg.harmonics + 1 == getattr(self, "orders", np.zeros(0)).size)
        present = self.fundamentals_hz.copy()
        self.nominal_hz = nominal
        self.orders = np.arange(1, cfg.harmonics + 2, dtype=float)
        self.reference_orders = np.asarray(cfg.reference_harmonics, dtype=float)
        self.timeout_samples = cfg.reference_timeout_s * self.sup.fs
        self.tracker = (FrequencyTracker(nominal, cfg.tracking_range_hz, self.sup.fs,
                                         loop_bandwidths_hz(nominal, self.orders),
                                         block_samples=self.block)
                        if cfg.frequency_tracking and nominal.size else None)
        self._record = (np.zeros((int(round(ACQUISITION_RECORD_S * self.sup.fs)),
                                  self.sup.channels)) if self.tracker is not None else None)
        self._record_n = 0
        self.active = bool(nominal.size) and (self.tracker is not None
                                               or self.reference_orders.size > 0)
        self._integrating_from = -1
        self.sup.canceller.set_integral_ratio(0.0)
        self.reference_state = "waiting" if self.reference_orders.size else "unused"
        self.count = 0
        self._previous_w = None
        self.fundamentals_hz = nominal.copy()
        self.acquired_hz = np.full(nominal.size, np.nan)
        if not same:
            self._p_at_hz = bank_frequencies(nominal, cfg.harmonics)
            return
        if self.tracker is not None:
            self.tracker.reset(present)
            target = self.tracker.frequencies_hz
        else:
            target = nominal
        if self.sup.canceller.tone_frequencies_hz.size == target.size * self.orders.size:
            self._retune(target)

    def set_reference(self, frequency_hz: float, index: int) -> None:
        """Store a tachometer value (Hz) of sample ``index``; slope from the previous one."""
        try:
            value = float(frequency_hz)
        except (TypeError, ValueError):
            value = float("nan")
        if not np.isfinite(value) or value <= 0.0:
            if not self._ignoring:         # once until a usable value comes (no flood)
                self.sup._event("warn", f"reference frequency {frequency_hz!r} ignored: "
                                        "not a finite frequency > 0 Hz")
            self._ignoring = True
            return
        self._ignoring = False
        if index > self.reference_index >= 0 and np.isfinite(self.reference_hz):
            self.reference_slope = (value - self.reference_hz) / (index - self.reference_index)
        self.reference_hz, self.reference_index = value, int(index)

    def step(self, index: int, error: np.ndarray) -> None:
        """Count the sample; at a block's end choose and apply the tones of the next one.

        With tracking, the error (C,) (m/s^2) of samples without control output and
        without excitation goes into a ring buffer: the record the tones are acquired
        from when adaptation starts (:meth:`_acquire_from_record`).
        """
        if self._record is not None:
            sup = self.sup
            if sup.identifier is None and sup.canceller.output_gain == 0.0:
                if self._record_broken:        # a new quiet stretch starts the record
                    self._record_n, self._record_broken = 0, False
                self._record[self._record_n % self._record.shape[0]] = error
                self._record_n += 1
            else:                              # kept: the stretch just before control on
                self._record_broken = True
        self.count += 1
        if self.count < self.block:
            return
        self.count = 0
        sup = self.sup
        if sup.guard.moved_away and self._detector[0] is not None:
            sup.guard.set_cancelled(np.einsum("tij,tj->ti", self._detector[0],
                                              sup.canceller.weights))
        if sup.identifier is not None or not sup.canceller.tone_frequencies_hz.size:
            self._previous_w, self._adapting_since = None, -1
            self._sweep_hz_per_s = None
            self._gate_integral(index)         # off: it restarts after its delay
            return
        fundamentals = self._from_reference(index)
        if fundamentals is not None:
            sweep = self.reference_rates_hz_per_s
        else:
            fundamentals = self._from_tracking(index)
            sweep = None if self.tracker is None else self.tracker.rates_hz_per_s
        if fundamentals is None:
            return
        self._retune(fundamentals)
        self._blocks += 1
        if self._blocks % SWEEP_CHECK_BLOCKS == 0:
            self._follow_sweep_rate(sweep)
            self._gate_integral(index)

    def _gate_integral(self, index: int) -> None:
        """Type-2 update for the tones that sweep, once they adapted with output a while.

        A tone sweeps when its fundamental moves faster than
        :data:`SWEEP_RATE_FLOOR_HZ_PER_S` (the reference's slope, or the tracker's learnt
        rate), and for :data:`SWEEP_HOLD_TIME_CONSTANTS` after. Off (the weights' rates
        cleared) for steady tones, and while the canceller is frozen, off or ramping; on
        :data:`INTEGRAL_DELAY_TIME_CONSTANTS` time constants after that ended. (A steady
        tone keeps the paper's update: with the tracker closing its loop on the weights'
        rotation, a type-2 update on a steady 1 % mismatch left 40-48 dB where the
        first-order update has 56-66 dB.)
        """
        canceller = self.sup.canceller
        running = (canceller.enabled and not canceller.frozen and canceller.mu > 0.0
                   and canceller.output_gain == 1.0 and bool(np.all(canceller.adapting)))
        ratio = self.sup.integral_ratio_setting
        sweep = self._sweep_hz_per_s
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
        if not fast.any() and self._never_swept():
            return                             # steady tones: the paper's update
        self._swept_at[fast] = index
        scale = np.broadcast_to(self._tone_rate_scale(), (size,))
        hold = SWEEP_HOLD_TIME_CONSTANTS / (canceller.mu * np.maximum(scale, 1e-6))
        sweeping = index - np.tile(self._swept_at, size // sweep.size) <= hold
        wanted = ratio * scale * sweeping
        if not np.array_equal(wanted, canceller.integral_ratio):
            canceller.set_integral_ratio(wanted)

    def _never_swept(self) -> bool:
        """True while no tone has swept since the type-2 update was last cleared."""
        return bool(np.all(np.isneginf(self._swept_at)))

    def _tone_rate_scale(self) -> np.ndarray | float:
        """Each oscillator's rate relative to mu (a mu policy's per-tone rates in P).

        So that every tone's type-2 loop has the same damping: ``kappa_t = R mu_t``.
        """
        choice = self.sup.mu_choice
        size = self.sup.canceller.tone_frequencies_hz.size
        if choice is None or choice.tone_mu.shape != (size,) or not choice.mu > 0.0:
            return 1.0
        return choice.tone_mu / choice.mu

    def _follow_sweep_rate(self, sweep_hz_per_s: np.ndarray | None) -> None:
        """Scale the weights' rates of change (type-2 update) down with a falling sweep rate.

        While a tone sweeps, its weights' rate of change is the converged weight's slope
        over frequency times the sweep rate (Hz/s: the reference's slope, or the tracker's
        learnt rate): when the sweep slows or stops (a spin-up reaching its speed), the
        rate the integrator learnt is scaled by the ratio of the new to the old sweep rate
        (within 0..1) instead of running on until the residual unlearns it. Only for
        tones that were sweeping faster than :data:`SWEEP_RATE_FLOOR_HZ_PER_S`.
        """
        canceller = self.sup.canceller
        previous = self._sweep_hz_per_s
        self._sweep_hz_per_s = None if sweep_hz_per_s is None else np.asarray(
            sweep_hz_per_s, dtype=float).copy()
        if (previous is None or sweep_hz_per_s is None
                or previous.shape != self._sweep_hz_per_s.shape
                or not canceller.integrating):
            return
        sweeping = np.abs(previous) > SWEEP_RATE_FLOOR_HZ_PER_S
        if not np.any(sweeping):
            return
        factor = np.ones(previous.size)
        factor[sweeping] = np.clip(self._sweep_hz_per_s[sweeping] / previous[sweeping],
                                   0.0, 1.0)
        if np.all(factor == 1.0):
            return
        orders = canceller.tone_frequencies_hz.size // previous.size
        rates = canceller.weight_rates * np.tile(factor, orders)[:, None]
        canceller.set_weight_rates(rates)

    def _from_reference(self, index: int) -> np.ndarray | None:
        """Order x reference (extrapolated to the block's middle) while fresh, else None."""
        if not self.reference_orders.size:
            return None
        fresh = self.reference_index >= 0 and index - self.reference_index <= self.timeout_samples
        state = "following" if fresh else ("stale" if self.reference_index >= 0 else "waiting")
        if state != self.reference_state:
            self._reference_changed(state)
        if not fresh:
            return None
        ahead = index - self.reference_index + 0.5 * self.block
        reference = self.reference_hz + self.reference_slope * ahead
        nyquist = 0.5 * self.sup.fs
        top = self.reference_orders * self.orders[-1]
        fundamentals = np.clip(self.reference_orders * reference, 1e-3 * nyquist,
                               0.999 * nyquist * self.reference_orders / top)
        if self.tracker is not None:       # a stale reference hands over from here
            self.tracker.reset(fundamentals, self.reference_rates_hz_per_s)
        # adaptation that starts on the reference needs no acquisition, and a later
        # handover to tracking is not a start (the record is from before control on)
        self._adaptation_started(index)
        self._previous_w = None
        return fundamentals

    @property
    def reference_rates_hz_per_s(self) -> np.ndarray:
        """Each fundamental's rate of change (Hz/s) on the reference: order x its slope."""
        return self.reference_slope * self.sup.fs * self.reference_orders

    def _adaptation_rate(self) -> float:
        """The rate the weights adapt at now (mu; 0 while off or frozen)."""
        canceller = self.sup.canceller
        return canceller.mu if canceller.enabled and not canceller.frozen else 0.0

    def _adaptation_started(self, index: int) -> bool:
        """Note when adaptation runs since (sample ``index`` if it starts now: True)."""
        if self._adaptation_rate() <= 0.0:
            self._adapting_since = -1
            return False
        if self._adapting_since >= 0:
            return False
        self._adapting_since = index
        return True

    def _reference_changed(self, state: str) -> None:
        if state == "stale":
            held = np.round(self.fundamentals_hz, 3).tolist()
            if self.tracker is None:
                then = f"hold at {held} Hz, held there until it comes back"
            else:
                rates = np.round(self.tracker.rates_hz_per_s, 3).tolist()
                then = (f"at {held} Hz, tracking from there at the reference's last rate "
                        f"{rates} Hz/s")
            self.sup._event("warn", f"reference frequency stale (none for "
                                    f"{self.sup.config.reference_timeout_s:g} s): tones "
                                    f"{then}")
            if self.tracker is not None:   # not back to nominal: a spin-up is far from it
                self.tracker.recentre(self.fundamentals_hz, self.tracker.rates_hz_per_s)
        elif state == "following":
            self.sup._event("info", f"following the reference frequency "
                                    f"({self.reference_hz:g} Hz): tones at "
                                    f"{self.reference_orders.tolist()} x reference")
        self.reference_state = state

    def _from_tracking(self, index: int) -> np.ndarray | None:
        """The tracker's frequencies for the next block (None: no tracker)."""
        if self.tracker is None:
            return None
        canceller = self.sup.canceller
        weights = canceller.adapted_weights      # the update low-pass's lag left out
        previous, self._previous_w = self._previous_w, weights
        t = self.nominal_hz.size
        if self._adaptation_started(index):
            self._acquire_from_record()
            return self.tracker.frequencies_hz
        rate = self._adaptation_rate()
        plant, inverse = self._detector_matrices()
        effective = rate * self._rate_scale               # a mu policy's per-tone rates
        if (previous is None or plant is None or rate <= 0.0
                or index - self._adapting_since < SETTLE_TIME_CONSTANTS / effective):
            # still settling after adaptation started: the tones coast on the acquired
            # rate (frozen or not adapting: they hold)
            return self.tracker.update(np.zeros(t), np.zeros(t, bool), effective,
                                       coast=rate > 0.0 and plant is not None)
        error, strength = weight_phase_error(previous, weights, rate, self.block, plant,
                                             inverse)
        strength = np.where(canceller.adapting, strength, 0.0)
        fundamental_error, valid = combine_orders(error.reshape(-1, t),
                                                  strength.reshape(-1, t), self.orders)
        # the detector's gain rises from 0 to 1 over the next time constant: the weights
        # are not converged yet and their first measurements kick the loop
        elapsed = (index - self._adapting_since) * effective - SETTLE_TIME_CONSTANTS
        fundamental_error = fundamental_error * min(1.0, elapsed / DETECTOR_RAMP_TIME_CONSTANTS)
        return self.tracker.update(fundamental_error, valid, effective)

    def _detector_matrices(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """G and P^-1 (T, C, C) at the oscillators for the phase detector (None: no G yet).

        G is the broadband response at the frequencies P was last computed for, else the
        tone-identified one; P^-1 is recomputed when the canceller's P changes.
        """
        sup, canceller = self.sup, self.sup.canceller
        p = canceller.coefficients_view
        if self._detector_source is not p:
            g = sup.plant_response
            if sup.plant_frequency_response is not None and g is not None:
                g = sup.plant_frequency_response.at(self._p_at_hz)
            if g is None or g.shape != p.shape:
                return None, None
            try:
                self._detector = (g, np.linalg.inv(p))
                normal = adaptation.normalized_coefficients(g, sup.config.adaptation)
            except (ValueError, np.linalg.LinAlgError):
                return None, None
            # the rate each tone adapts at relative to mu: |P| / |P normalised on G|, the
            # slowest of the fundamentals' orders (the settling waits for it)
            self._rate_scale = float(np.clip(_norm_ratio(p, normal).min(), 1e-6, None))
            self._detector_source = p
        return self._detector

    def _acquire_from_record(self) -> None:
        """Adaptation starts: each tone at the strongest line of the last record, if any.

        The record (:data:`ACQUISITION_RECORD_S` of error without control output or
        excitation, just before) says where the disturbance is now (a drifting line has
        moved since the identification); the tones and the tracker start there and the
        phase-locked loop only fine-tracks. Reported as an event (``acquired_hz``).
        """
        size = self._record.shape[0]
        if self._record_n < size:
            return
        start = self._record_n % size
        record = np.concatenate([self._record[start:], self._record[:start]])
        found = strongest_lines_hz(record, self.sup.fs, self.tracker.lower_hz,
                                   self.tracker.upper_hz)
        slope = self._record_slopes_hz_per_s(record, found)
        # the record's window does not resolve lines closer than its main lobe's half
        # width (2 / record length): a tone with a neighbour that close keeps its place
        # (close_tones, 39 and 40 Hz: the 1 s record put them at 38.70 and 40.33 Hz)
        others = np.abs(found[:, None] - self.fundamentals_hz[None, :])
        np.fill_diagonal(others, np.inf)
        found[np.min(others, axis=1, initial=np.inf) < 2.0 / ACQUISITION_RECORD_S] = np.nan
        if not np.any(np.isfinite(found)):
            return
        self.acquired_hz = found
        # the line measured over the record is where it was at the record's middle: a
        # drifting line has moved on by half a record since
        now = found + 0.5 * ACQUISITION_RECORD_S * slope
        target = np.where(np.isfinite(found), now, self.fundamentals_hz)
        self.tracker.reset(target, np.where(np.isfinite(found), slope, 0.0))
        self._retune(self.tracker.frequencies_hz)
        self._previous_w = None
        self.sup._event("info", "acquisition at control on: tones " + ", ".join(
            f"{n:g} -> {f:.3f} Hz ({r:+.3f} Hz/s)" if np.isfinite(a) else f"{n:g} Hz (no line)"
            for n, f, a, r in zip(self.nominal_hz, self.fundamentals_hz, found, slope,
                                  strict=True))
            + f" (strongest line of the last {ACQUISITION_RECORD_S:g} s)")

    def _record_slopes_hz_per_s(self, record: np.ndarray, found: np.ndarray) -> np.ndarray:
        """Each found line's rate of change (Hz/s) from the record's two halves (0: none).

        The strongest line of each half within +-:data:`ACQUISITION_SLOPE_WINDOW_HZ` of
        the whole record's; a half without it, or a tone without a line, gives 0.
        """
        half = record.shape[0] // 2
        window = ACQUISITION_SLOPE_WINDOW_HZ
        lower = np.where(np.isfinite(found), found - window, self.tracker.lower_hz)
        upper = np.where(np.isfinite(found), found + window, self.tracker.upper_hz)
        first = strongest_lines_hz(record[:half], self.sup.fs, lower, upper)
        second = strongest_lines_hz(record[half:], self.sup.fs, lower, upper)
        slope = (second - first) / (half / self.sup.fs)
        return np.where(np.isfinite(slope) & np.isfinite(found), slope, 0.0)

    def acquire(self, lines: list[RemovedLine]) -> None:
        """Start each tone at the strongest disturbance line within its tracking bounds.

        After a broadband identification (the lines it fitted and removed, and those on
        its grid): the oscillators (all orders) and the tracker move there at once, the
        caller computes P from G(f) at them; a tone with no line there stays put. Reported
        as an event and in ``acquired_hz`` (NaN: none).
        """
        cfg = self.sup.config
        freqs = np.array([line.frequency_hz for line in lines], dtype=float)
        strength = np.array([float(np.linalg.norm(line.amplitude)) for line in lines])
        found = acquisition_frequencies(self.nominal_hz, cfg.tracking_range_hz, self.sup.fs,
                                        freqs, strength)
        self.acquired_hz = found
        if not np.any(np.isfinite(found)):
            self.sup._event("info", "acquisition: no disturbance line within the tracking "
                                    "range of the tones; tracking starts at "
                                    f"{self.fundamentals_hz.tolist()} Hz")
            return
        target = np.where(np.isfinite(found), found, self.fundamentals_hz)
        self.tracker.reset(target)
        self.fundamentals_hz = self.tracker.frequencies_hz
        self._previous_w = None
        bank = (self.orders[:, None] * self.fundamentals_hz[None, :]).reshape(-1)
        self.sup.canceller.retune(bank)
        self.sup.guard.follow_tones(bank)
        self._p_at_hz = bank
        self.sup._event("info", "acquisition: tones " + ", ".join(
            f"{n:g} -> {f:.3f} Hz" if np.isfinite(a) else f"{n:g} Hz (no line)"
            for n, f, a in zip(self.nominal_hz, self.fundamentals_hz, found, strict=True))
            + " (strongest disturbance line within the tracking range)")

    def _retune(self, fundamentals: np.ndarray) -> None:
        """Move every oscillator to its order x fundamental; a new P from G(f) if it moved.

        See :data:`P_RETUNE_HZ` and :data:`P_RETUNE_CHANGE`; the weights are not touched.
        """
        self.fundamentals_hz = np.asarray(fundamentals, dtype=float).copy()
        bank = (self.orders[:, None] * self.fundamentals_hz[None, :]).reshape(-1)
        canceller = self.sup.canceller
        canceller.retune(bank)
        self.sup.guard.follow_tones(bank)
        response = self.sup.plant_frequency_response
        if (response is None or self.sup.plant_response is None
                or np.max(np.abs(bank - self._p_at_hz)) < P_RETUNE_HZ
                or not np.all(canceller.adapting)):     # tones waiting for identification
            return
        try:
            g_old, g_new = response.at(self._p_at_hz), response.at(bank)
            mode = self.sup.config.adaptation
            coefficients = adaptation.normalized_coefficients(g_new, mode)
            # keep each tone's own rate (a mu policy folds per-tone rates into P)
            reference = adaptation.normalized_coefficients(g_old, mode)
            present = canceller.coefficients_view
            coefficients = coefficients * _norm_ratio(present, reference)[:, None, None]
        except (ValueError, np.linalg.LinAlgError):     # G(f) unusable there: keep P
            return
        if np.max(_norm_ratio(coefficients - present, present)) < P_RETUNE_CHANGE:
            return
        # Only P moves; the weights are left to the adaptation. Carrying them through the
        # plant's change of response (W -> G_new^-1 G_old W) assumed the disturbance at
        # the accelerometers does not change with the frequency, but it comes through the
        # same structure (and a rotor's grows with the speed squared); each carry was a
        # step of the output that the adaptation then undid. Measured on the core loop
        # against the uncontrolled twin, last 10 s of ``drift_tracking``, seeds 4/11/12:
        # largest third-octave rise +3.1/+2.8/+3.5 dB (44.7-56.2 Hz) with the carry,
        # +1.2/+0.6/+0.7 dB without; the tone's band 1 dB better without; ``spin_up``
        # order 1 over the ramp 46 -> 52 dB median.
        canceller.set_coefficients(coefficients)
        self._p_at_hz = bank

    def status(self) -> dict[str, Any]:
        """The status keys of the moving tones (for ``/diagnostics``)."""
        return {"tone_estimates_hz": [float(f) for f in self.fundamentals_hz],
                "acquired_hz": [float(f) for f in self.acquired_hz],
                "guard_bands": ("fixed" if not self.sup.guard.following else
                                "moved away" if self.sup.guard.moved_away else "following"),
                "frequency_tracking": self.tracker is not None,
                "reference": self.reference_state,
                "bank_tones_hz": [float(f) for f in self.sup.canceller.tone_frequencies_hz]}
