"""The tone set in force each block: nominal, tracked or reference-driven, with harmonics.

Every :data:`~hexapod_vibration.core.control.frequency_tracker.DEFAULT_BLOCK_SAMPLES`
samples (when tracking or a reference is configured) the fundamentals are chosen:
``order_k x reference`` while the reference is fresh (:mod:`.reference_input`), else the
:class:`~hexapod_vibration.core.control.frequency_tracker.FrequencyTracker` estimate when
``frequency_tracking`` is on (:mod:`.phase_detector`), else nominal; the canceller's
oscillators (all orders) are retuned to them phase-continuously (:mod:`.retuning`), and
sweeping tones adapt with the type-2 update (:mod:`.sweep_gate`). While the plant is
identified the tones hold. The tones are acquired before tracking starts
(:mod:`.acquisition`). A stale tachometer leaves the tones where it had them (tracking goes
on from there). The guard's tone bands follow the oscillators (its reference is kept).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod_vibration.core.control.divergence_guard import DivergenceGuard
from hexapod_vibration.core.control.frequency_tracker import (
    ACQUISITION_RECORD_S,
    DEFAULT_BLOCK_SAMPLES,
    FrequencyTracker,
    loop_bandwidths_hz,
    rate_bandwidth_caps_hz,
)
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.plant_identification import RemovedLine
from hexapod_vibration.core.control.supervisor.acquisition import Acquisition
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.phase_detector import PhaseDetector
from hexapod_vibration.core.control.supervisor.planning import bank_frequencies
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy
from hexapod_vibration.core.control.supervisor.reference_input import (
    ReferenceInput,
    ReferenceState,
)
from hexapod_vibration.core.control.supervisor.retuning import Retuner
from hexapod_vibration.core.control.supervisor.sweep_gate import SWEEP_CHECK_BLOCKS, SweepGate

FOLLOW_SETTINGS = ("frequency_tracking", "tracking_range_hz", "reference_harmonics",
                   "reference_timeout_s", "harmonics", "tone_frequencies_hz")
"""Settings after whose change the follower starts again (:meth:`ToneFollower.rebuild`)."""


class ToneFollower:
    """Chooses the fundamentals each block and moves the oscillators there.

    Args:
        settings: the settings in force.
        canceller: the canceller whose oscillators follow.
        guard: the divergence guard whose tone bands follow.
        plant: what the identifications found (G, G(f)).
        rates: the rate policy (per-tone rates).
        events: where the reference's and the acquisition's news are reported.
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 guard: DivergenceGuard, plant: PlantKnowledge, rates: RatePolicy,
                 events: EventLog) -> None:
        """Idle until :meth:`rebuild` reads the settings."""
        self._settings, self._canceller, self._guard = settings, canceller, guard
        self._events = events
        self.active = False
        """True when the tones may move (tracking or a reference): :meth:`step` each sample."""
        self.block = DEFAULT_BLOCK_SAMPLES
        self._count = 0
        self._blocks = 0                       # blocks retuned (SWEEP_CHECK_BLOCKS)
        self.nominal_hz: np.ndarray | None = None
        self.orders = np.zeros(0)
        self.fundamentals_hz = np.zeros(0)
        """(T,) the frequency (Hz) each configured tone's oscillator runs at now."""
        self.acquired_hz = np.zeros(0)
        """(T,) where the last acquisition found each tone's line (Hz, NaN: none)."""
        self.tracker: FrequencyTracker | None = None
        self.reference = ReferenceInput(settings.fs, events)
        self._acquisition = Acquisition(settings.fs, settings.channels)
        self._detector = PhaseDetector(settings, canceller, plant)
        self._retuner = Retuner(settings, canceller, guard, plant)
        self._rates = rates
        self._limited_at_mu = float("nan")
        self._sweep = SweepGate(settings, canceller, rates)

    def rebuild(self) -> None:
        """Re-read the settings; the tracker restarts from where the tones are.

        New tones or orders start at nominal; otherwise tracked tones keep their present
        frequencies (within the new bounds) and untracked ones go back to nominal, with
        the oscillators retuned phase-continuously.
        """
        cfg, fs = self._settings.config, self._settings.fs
        nominal = np.asarray(cfg.tone_frequencies_hz, dtype=float)
        same = (np.array_equal(nominal, self.nominal_hz)
                and cfg.harmonics + 1 == self.orders.size)
        present = self.fundamentals_hz.copy()
        self.nominal_hz = nominal
        self.orders = np.arange(1, cfg.harmonics + 2, dtype=float)
        self.reference.configure(cfg.reference_harmonics, cfg.reference_timeout_s)
        self.tracker = (FrequencyTracker(nominal, cfg.tracking_range_hz, fs,
                                         loop_bandwidths_hz(nominal, self.orders),
                                         block_samples=self.block)
                        if cfg.frequency_tracking and nominal.size else None)
        self._acquisition.reset(self.tracker is not None)
        self.limit_bandwidth()
        self.active = bool(nominal.size) and (self.tracker is not None
                                               or self.reference.orders.size > 0)
        self._sweep.restart()
        self._count = 0
        self._detector.previous_w = None
        self.fundamentals_hz = nominal.copy()
        self.acquired_hz = np.full(nominal.size, np.nan)
        if not same:
            self._retuner.p_at_hz = bank_frequencies(nominal, cfg.harmonics)
            return
        if self.tracker is not None:
            self.tracker.reset(present)
            target = self.tracker.frequencies_hz
        else:
            target = nominal
        if self._canceller.tone_frequencies_hz.size == target.size * self.orders.size:
            self._retune(target)

    def limit_bandwidth(self) -> None:
        """Each tracked tone's loop no faster than its weights allow (the rates in force).

        :func:`~hexapod_vibration.core.control.frequency_tracker.rate_bandwidth_caps_hz`
        of :meth:`RatePolicy.tone_rates`; again whenever ``mu`` changes (:meth:`step`).
        """
        self._limited_at_mu = self._canceller.mu
        rates = self._rates.tone_rates()
        if self.tracker is None or rates.size != self.orders.size * self.nominal_hz.size:
            return
        self.tracker.limit_bandwidth(rate_bandwidth_caps_hz(self.orders, rates,
                                                            self._settings.fs))

    def step(self, index: int, error: np.ndarray, identifying: bool) -> None:
        """Count sample ``index``; at a block's end choose and apply the next block's tones.

        With tracking, the error (C,) (m/s^2) of samples without control output and
        without excitation (``identifying``: the plant is being identified) is recorded for
        the acquisition when adaptation starts.
        """
        canceller = self._canceller
        if self._acquisition.record is not None:
            self._acquisition.take(error, not identifying and canceller.output_gain == 0.0)
        self._count += 1
        if self._count < self.block:
            return
        self._count = 0
        if self._canceller.mu != self._limited_at_mu:
            self.limit_bandwidth()
        plant_matrix = self._detector.matrices[0]
        if self._guard.moved_away and plant_matrix is not None:
            self._guard.set_cancelled(np.einsum("tij,tj->ti", plant_matrix, canceller.weights))
        if identifying or not canceller.tone_frequencies_hz.size:
            self._detector.stop()
            self._sweep.sweep_hz_per_s = None
            self._sweep.gate(index)            # off: it restarts after its delay
            return
        fundamentals = self._from_reference(index)
        if fundamentals is not None:
            sweep = self.reference.rates_hz_per_s
        else:
            fundamentals = self._from_tracking(index)
            sweep = None if self.tracker is None else self.tracker.rates_hz_per_s
        if fundamentals is None:
            return
        self._retune(fundamentals)
        self._blocks += 1
        if self._blocks % SWEEP_CHECK_BLOCKS == 0:
            self._sweep.follow(sweep)
            self._sweep.gate(index)

    def _from_reference(self, index: int) -> np.ndarray | None:
        """Order x reference (extrapolated to the block's middle) while fresh, else None."""
        reference = self.reference
        if not reference.orders.size:
            return None
        state = reference.state_at(index)
        if state != reference.state:
            self._reference_changed(state)
        if state is not ReferenceState.FOLLOWING:
            return None
        fundamentals = reference.fundamentals_hz(index, self.block, self.orders[-1])
        if self.tracker is not None:       # a stale reference hands over from here
            self.tracker.reset(fundamentals, reference.rates_hz_per_s)
        # adaptation that starts on the reference needs no acquisition, and a later
        # handover to tracking is not a start (the record is from before control on)
        self._detector.adaptation_started(index)
        self._detector.previous_w = None
        return fundamentals

    def _reference_changed(self, state: ReferenceState) -> None:
        """Report the reference's new state; a stale one hands over to tracking."""
        if state is ReferenceState.STALE:
            held = np.round(self.fundamentals_hz, 3).tolist()
            if self.tracker is None:
                then = f"hold at {held} Hz, held there until it comes back"
            else:
                rates = np.round(self.tracker.rates_hz_per_s, 3).tolist()
                then = (f"at {held} Hz, tracking from there at the reference's last rate "
                        f"{rates} Hz/s")
            self._events.add("warn", f"reference frequency stale (none for "
                                     f"{self._settings.config.reference_timeout_s:g} s): "
                                     f"tones {then}")
            if self.tracker is not None:   # not back to nominal: a spin-up is far from it
                self.tracker.recentre(self.fundamentals_hz, self.tracker.rates_hz_per_s)
        elif state is ReferenceState.FOLLOWING:
            self._events.add("info", f"following the reference frequency "
                                     f"({self.reference.hz:g} Hz): tones at "
                                     f"{self.reference.orders.tolist()} x reference")
        self.reference.state = state

    def _from_tracking(self, index: int) -> np.ndarray | None:
        """The tracker's frequencies for the next block (None: no tracker)."""
        if self.tracker is None:
            return None
        tracked = self._detector.step(index, self.tracker, self.orders, self.nominal_hz.size,
                                      self.block, self._retuner.p_at_hz)
        if tracked is None:                    # adaptation starts: acquire first
            self._acquire_from_record()
            return self.tracker.frequencies_hz
        return tracked

    def _acquire_from_record(self) -> None:
        """Adaptation starts: each tone at the strongest line of the last record, if any.

        The record (:data:`ACQUISITION_RECORD_S` of error without control output or
        excitation, just before) says where the disturbance is now (a drifting line has
        moved since the identification); the tones and the tracker start there and the
        phase-locked loop only fine-tracks. Reported as an event (``acquired_hz``).
        """
        acquired = self._acquisition.from_record(self.tracker, self.fundamentals_hz)
        if acquired is None:
            return
        found, slope = acquired
        if not np.any(np.isfinite(found)):
            return
        self.acquired_hz = found
        # the line measured over the record is where it was at the record's middle: a
        # drifting line has moved on by half a record since
        now = found + 0.5 * ACQUISITION_RECORD_S * slope
        target = np.where(np.isfinite(found), now, self.fundamentals_hz)
        self.tracker.reset(target, np.where(np.isfinite(found), slope, 0.0))
        self._retune(self.tracker.frequencies_hz)
        self._detector.previous_w = None
        self._events.add("info", "acquisition at control on: tones " + ", ".join(
            f"{n:g} -> {f:.3f} Hz ({r:+.3f} Hz/s)" if np.isfinite(a) else f"{n:g} Hz (no line)"
            for n, f, a, r in zip(self.nominal_hz, self.fundamentals_hz, found, slope,
                                  strict=True))
            + f" (strongest line of the last {ACQUISITION_RECORD_S:g} s)")

    @property
    def acquires(self) -> bool:
        """True when a broadband identification's lines place the tones (:meth:`acquire`).

        That is with tracking on and no fresh reference.
        """
        return self.tracker is not None and self.reference.state != ReferenceState.FOLLOWING

    def acquire(self, lines: list[RemovedLine]) -> None:
        """Start each tone at the strongest disturbance line within its tracking bounds.

        After a broadband identification (the lines it fitted and removed, and those on
        its grid): the oscillators (all orders) and the tracker move there at once, the
        caller computes P from G(f) at them; a tone with no line there stays put. Reported
        as an event and in ``acquired_hz`` (NaN: none).
        """
        found = self._acquisition.from_lines(lines, self.nominal_hz,
                                             self._settings.config.tracking_range_hz)
        self.acquired_hz = found
        if not np.any(np.isfinite(found)):
            self._events.add("info", "acquisition: no disturbance line within the tracking "
                                     "range of the tones; tracking starts at "
                                     f"{self.fundamentals_hz.tolist()} Hz")
            return
        target = np.where(np.isfinite(found), found, self.fundamentals_hz)
        self.tracker.reset(target)
        self.fundamentals_hz = self.tracker.frequencies_hz
        self._detector.previous_w = None
        self._retuner.move((self.orders[:, None] * self.fundamentals_hz[None, :]).reshape(-1))
        self._events.add("info", "acquisition: tones " + ", ".join(
            f"{n:g} -> {f:.3f} Hz" if np.isfinite(a) else f"{n:g} Hz (no line)"
            for n, f, a in zip(self.nominal_hz, self.fundamentals_hz, found, strict=True))
            + " (strongest disturbance line within the tracking range)")

    def _retune(self, fundamentals: np.ndarray) -> None:
        """Every oscillator to its order x fundamental (:class:`~.retuning.Retuner`)."""
        self.fundamentals_hz = np.asarray(fundamentals, dtype=float).copy()
        self._retuner.retune((self.orders[:, None] * self.fundamentals_hz[None, :]).reshape(-1))

    def status(self) -> dict[str, Any]:
        """The status keys of the moving tones (for ``/diagnostics``)."""
        guard = self._guard
        return {"tone_estimates_hz": [float(f) for f in self.fundamentals_hz],
                "acquired_hz": [float(f) for f in self.acquired_hz],
                "guard_bands": ("fixed" if not guard.following else
                                "moved away" if guard.moved_away else "following"),
                "frequency_tracking": self.tracker is not None,
                "reference": self.reference.state.value,
                "bank_tones_hz": [float(f) for f in self._canceller.tone_frequencies_hz]}
