"""The plant's identification, from its first sample to control in force (or refused).

The normalised adaptation modes (``decentralized``, ``centralized``) wait for an
identification of the plant at their tones; ``raw`` (P = I) adapts from the first sample
and its identification only measures G and the bound. The canceller is frozen meanwhile
and its output stays as it was.

- ``identification: tones``: test tones at the tones
  (:class:`~hexapod_vibration.core.control.adaptation.ToneResponseIdentifier`), G at each,
  the bound of eq. 18; its confidence is how far the disturbance moved between its two
  baselines (refused above :data:`MAX_BASELINE_CHANGE`);
- ``identification: broadband``: a 10 s multisine over 0..fs/2
  (:class:`~hexapod_vibration.core.control.plant_identification.BroadbandIdentifier`,
  off-grid disturbance lines fitted and removed): G(f), the Nyquist bound on it, the mu
  policy and the predicted sensitivity; refused above
  :data:`MAX_IDENTIFICATION_UNCERTAINTY` at the tones.

The analysis of a finished identification runs one piece per sample
(:meth:`PlantIdentification.step`), ending with what it measured put in force
(:class:`~.engagement.ControlEngagement`): with G(f) each Nyquist test takes ~25 ms, and the
lockstep driver waits at most ``lockstep_timeout_s`` for a sample's command. Its heavy
computations are jobs (:mod:`.analysis_jobs`): inline by default, on a worker process beside
a realtime loop (the loop then keeps its deadline while the analysis waits for them).
"""

from __future__ import annotations

from collections.abc import Generator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod_vibration.core.control import adaptation
from hexapod_vibration.core.control.held_inputs import HeldCommands
from hexapod_vibration.core.control.plant_identification import (
    BroadbandIdentifier,
    DisturbanceSpectrum,
    PlantFrequencyResponse,
    RemovedLine,
)
from hexapod_vibration.core.control.supervisor.analysis_jobs import (
    Analysis,
    Job,
    JobRunner,
    Pieces,
)
from hexapod_vibration.core.control.supervisor.engagement import ControlEngagement
from hexapod_vibration.core.control.supervisor.parts import SupervisorParts
from hexapod_vibration.core.control.supervisor.planning import Plan
from hexapod_vibration.core.control.supervisor.stall_restart import (
    STALL_REFUSAL,
    StallRestart,
)

MAX_IDENTIFICATION_UNCERTAINTY = 0.1
"""An identification whose relative uncertainty at a tone exceeds this is refused (10 %:
a gain within 10 % and a phase within ~6 degrees)."""
MAX_BASELINE_CHANGE = 0.25
"""The tone identification is refused when the disturbance at a tone moved by more than
this fraction of the response between its two baselines (0.4 Hz off the tone: 48 %; a plant
still settling 0.2 s after start-up: 12 %, whose G is still within 3 %)."""


@dataclass(frozen=True)
class _Measurement:
    """A finished identification's G at its tones and how far it can be trusted."""

    response: np.ndarray
    uncertainty: float
    limit: float
    what: str
    lines: Sequence[RemovedLine] = ()
    """The record's strong disturbance lines (a broadband record; none from tones)."""


@dataclass(frozen=True)
class BroadbandAnalysis:
    """What a finished broadband record gives (:func:`analyse_broadband`)."""

    response: PlantFrequencyResponse
    disturbance: DisturbanceSpectrum
    at_tones: np.ndarray
    """G (T, C, C) at the tones ((m/s^2)/N)."""
    uncertainty: float
    """The largest relative uncertainty of G at the tones."""
    lines: list[RemovedLine]
    """The record's strong disturbance lines."""


def analyse_broadband(identifier: BroadbandIdentifier, tones: list[float]
                      ) -> BroadbandAnalysis:
    """G(f), the disturbance's spectrum and lines of a finished record; G at ``tones`` (Hz).

    A pure job (the heaviest of the analysis, ~0.2 s): the identifier's copy on a worker.
    """
    response = identifier.result()
    return BroadbandAnalysis(response, identifier.disturbance(), response.at(tones),
                             float(np.max(response.uncertainty_at(tones))),
                             identifier.disturbance_lines())


class PlantIdentification:
    """Runs one identification at a time and puts its result in force.

    Args:
        parts: the supervisor's collaborators: the canceller frozen while identifying (its P
            set after), the clock (the identification's span), the plant's knowledge (what
            was found), the rates, the gate (refuses control or lets it run again), the
            safety monitor (its reference waits for the excitation's decay), the follower
            (the tones acquired on the lines found), the event log.
        jobs: where the analysis's heavy computations run (inline, or a worker).
    """

    def __init__(self, parts: SupervisorParts, jobs: JobRunner) -> None:
        """None running."""
        self._settings, self._canceller, self._clock = (parts.settings, parts.canceller,
            parts.clock)
        self._plant, self._rates, self._gate = parts.plant, parts.rates, parts.gate
        self._safety, self._follower, self._events = (parts.safety, parts.follower,
            parts.events)
        self._engagement = ControlEngagement(parts)
        self.identifier: adaptation.ToneResponseIdentifier | BroadbandIdentifier | None = None
        """The identification injecting its excitation, None: none."""
        self.tones: list[float] = []
        """The tones (Hz) the last identification measured at."""
        self.start_sample = -1
        self.end_sample = -1
        self.analysis: Pieces | None = None
        """The analysis of the finished identification, one piece per sample; None: none."""
        self._jobs = jobs
        self.held = HeldCommands()
        """The driver's reports of the commands it held (a realtime driver)."""
        self.stall = StallRestart()
        """An identification a stall of the loop disturbed, waiting to start again."""
        self._observed: dict[int, np.ndarray] = {}

    @property
    def running(self) -> bool:
        """True while the excitation is injected."""
        return self.identifier is not None

    @property
    def busy(self) -> bool:
        """True while running, analysing or waiting to start again (``identifying``)."""
        return self.identifier is not None or self.analysis is not None or self.stall.waiting

    def start(self, tones: list[float] | None, first_sample: int) -> str:
        """Start an identification whose first sample is ``first_sample``; freeze the weights.

        Args:
            tones: tones to identify (Hz); None: the canceller's tones.
            first_sample: its first sample.

        Returns:
            A one-line description of the run (also reported).

        Raises:
            ValueError: there are no tones to identify.
        """
        tones = [float(f) for f in (tones if tones is not None
                                    else self._canceller.tone_frequencies_hz)]
        if not tones:
            raise ValueError("no tones to identify")
        self._abandon_analysis("a new identification starts")
        self.stall.clear()
        cfg, settings = self._settings.config, self._settings
        if cfg.identification == "broadband":
            self.identifier = BroadbandIdentifier(settings.channels, settings.fs)
            what = f"over 0..fs/2 (multisine) for the tones {tones} Hz"
        else:
            self.identifier = adaptation.ToneResponseIdentifier(
                settings.channels, tones, settings.fs, cfg.identification_amplitude_n,
                cfg.identification_settle_s, cfg.identification_measure_s)
            what = f"at {tones} Hz"
        self.tones = tones
        self._canceller.set_frozen(True)
        self.start_sample = first_sample
        self.held.forget_before(first_sample)
        self._observed.clear()                   # of a run started before (a new loop run)
        self.end_sample = -1
        text = f"identifying the plant {what} ({self.identifier.duration_s:.1f} s of samples)"
        self._events.add("info", text)
        return text

    def observe(self, index: int, error: np.ndarray) -> None:
        """Sample ``index``'s error (C,) (m/s^2), received but not acted on (see skip).

        Kept while an identification runs: when the gap is found, it is recorded, so the
        gap costs the sample's command only (held by the driver, which reports it).
        """
        if self.identifier is not None and self.analysis is None:
            self._observed[index] = error.copy()

    def skip(self, first: int, samples: int) -> None:
        """Samples ``first..first+samples-1`` were not acted on.

        The running identification records those observed (:meth:`observe`) and leaves
        the others out (a run finished by them is analysed at the next step).
        """
        observed, self._observed = self._observed, {}
        identifier = self.identifier
        if identifier is None or self.analysis is not None:
            return
        for index in range(first, first + samples):
            error = observed.get(index)
            if error is None:
                identifier.skip(1)
            else:
                identifier.step(error)          # recorded; its command was not sent

    def restart(self, first_sample: int) -> None:
        """Start the running identification again from ``first_sample``."""
        self.start(list(self.tones), first_sample)

    def stalled(self, first: int, settled: int) -> None:
        """The driver's watchdog stood in from applied sample ``first``; settled at ``settled``.

        A record that holds any of ``first..settled-1`` measured the stall: it is dropped
        (its analysis too) and starts again at ``settled`` (:mod:`.stall_restart`); past
        ``MAX_STALL_RESTARTS`` in a row it is refused.
        """
        identifier = self.identifier
        if identifier is None:
            if self.stall.waiting:                   # stalled again while settling
                self.stall.postpone(settled)
            return
        if not self.stall.disturbs(first, settled, self.start_sample,
                                   identifier.total_samples):
            return
        if self.analysis is not None:
            self.analysis.close()
            self.analysis = None
        self.identifier = None
        self.end_sample = self._clock.last           # its excitation stopped here
        if self.stall.schedule(settled):
            self._events.add("warn", self.stall.warning(first))
        else:
            self._plant.put_in_force(None, [])
            self._gate.refuse(STALL_REFUSAL)

    def start_when_due(self, index: int, gap: int) -> None:
        """At sample ``index`` (after ``gap`` missing): start the identification that is due.

        The start-up one ``identify_delay_s`` after the first sample, unless the plant is
        known or one runs (or there are no tones); a stalled one's restart
        (:mod:`.stall_restart`).
        """
        clock, cfg = self._clock, self._settings.config
        due = clock.first + int(round(cfg.identify_delay_s * self._settings.fs))
        if (index - gap <= due <= index      # reached now (a gap may have skipped it)
                and self._plant.response is None and self.identifier is None
                and cfg.auto_identify and self._canceller.tone_frequencies_hz.size):
            self.start(None, index)
        if self.stall.waiting and self.stall.due(index):
            restarts = self.stall.restarts
            self.start(list(self.tones), index)
            self.stall.restarts = restarts

    def retarget(self, plan: Plan, mode_changed: bool) -> None:
        """New tones or mode: identify what they need; stop an identification they do not.

        Known tones (or no tones) need none: a running one stops, bumplessly (an analysis
        in progress too, :meth:`_abandon_analysis`). Unknown tones do, in every mode:
        ``raw`` too, as at start-up, for the bound (P = I diverges where G's phase is
        beyond +-90 degrees, and nothing else would say so). A new mode freezes the
        weights (a normalised mode must not adapt with another mode's P); a broadband
        identification, running or waiting for its analysis, goes on for the new tones
        (its G(f) covers 0..fs/2); else, with ``auto_identify``, the new tones are
        identified from the next sample (unless they are being identified already).
        """
        if plan.response is not None or not plan.tones:
            analysed = self._abandon_analysis("the tones or the adaptation changed")
            if self.identifier is not None or analysed:
                self._events.add("info", "identification no longer needed: stopped")
                self.identifier = None
                self._gate.resume()
            return
        if mode_changed:
            self._canceller.set_frozen(True)
        if isinstance(self.identifier, BroadbandIdentifier):
            self._follow_tones(plan.tones)
            return
        self._abandon_analysis("the tones or the adaptation changed")
        running = self.identifier is not None and np.array_equal(self.tones, plan.tones)
        if self._settings.config.auto_identify and self._clock.first >= 0 and not running:
            self.start(plan.tones, self._clock.last + 1)

    def _follow_tones(self, tones: list[float]) -> None:
        """The running broadband identification measures G at ``tones`` (Hz) instead.

        Its record is the same for any tones; an analysis waiting for the driver's report
        (it has measured nothing yet) starts again for them.
        """
        self.tones = [float(f) for f in tones]
        if self.analysis is not None:
            self.analysis.close()
            self.analysis = Pieces(self._analyse(), self._jobs)
        self._events.add("info", f"the broadband identification goes on for the tones "
                                 f"{self.tones} Hz")

    def _abandon_analysis(self, why: str) -> bool:
        """Stop an analysis in progress (it works for the tones and mode it began with).

        Its pieces hold those tones' coefficients across samples: finished after a change
        they would put them on oscillators that no longer match. What it already learned
        (G in the plant's knowledge) stays. Returns True if one was stopped.
        """
        if self.analysis is None:
            return False
        self.analysis.close()
        self.analysis = self.identifier = None
        self._events.add("info", f"the identification's analysis stopped: {why}")
        return True

    def step(self, error: np.ndarray, command: np.ndarray) -> None:
        """Add the excitation to ``command`` (C,) (N); analyse once the record is complete.

        ``error``: the sample's DC-blocked accelerations (C,) (m/s^2).
        """
        if self.identifier is not None and self.analysis is None:
            command += self.identifier.step(error)
            if self.identifier.done:
                self.analysis = Pieces(self._analyse(), self._jobs)
                self._advance()
        elif self.analysis is not None:
            self._advance()

    def _advance(self) -> None:
        """One piece of the running analysis (or a sample of waiting for its job)."""
        if self.analysis.step():
            self.analysis = None
        lost = self._jobs.lost_news()
        if lost:
            self._events.add("warn", lost)

    def _measure(self) -> Generator[Job | None, Any, _Measurement]:
        """G at the tones from the finished identifier, into the plant's knowledge.

        A broadband record's analysis is one job (:func:`analyse_broadband`).
        """
        tones, identifier = self.tones, self.identifier
        if isinstance(identifier, BroadbandIdentifier):
            found: BroadbandAnalysis = yield Job(analyse_broadband, (identifier, tones))
            self._plant.learn_broadband(found.response, found.disturbance)
            return _Measurement(found.at_tones, found.uncertainty,
                                MAX_IDENTIFICATION_UNCERTAINTY,
                                "relative uncertainty of G(f) at the tones", found.lines)
        response = identifier.result()
        change = identifier.baseline_change()
        self._plant.learn_tones(tones, response)
        return _Measurement(response, float(np.max(change)), MAX_BASELINE_CHANGE,
                            "change of the disturbance at the tones during the identification")

    def _analyse(self) -> Analysis:
        """The analysis of a finished identification, one piece per sample (a generator).

        G, its confidence, the coefficients, the bound, the policy and the prediction. The
        canceller stays frozen and off meanwhile (state ``identifying``).
        """
        if isinstance(self.identifier, BroadbandIdentifier):
            corrected = yield from self.held.correct(self.identifier, self.start_sample)
            if corrected:
                self._events.add("info", corrected)
        missing = self.identifier.missing_refusal()
        if missing:
            self.identifier = None
            self.end_sample = self._clock.last
            self._plant.put_in_force(None, [])
            self._gate.refuse(f"identification refused: {missing}; control stays off "
                              "(~/identify to measure again)")
            return
        measured = yield from self._measure()
        identifier, self.identifier = self.identifier, None
        last = self._clock.last
        self.end_sample = last
        self._safety.quiet_after(last)
        self._plant.confidence = float(max(0.0, 1.0 - measured.uncertainty))
        self._rates.forget_choice()
        broadband = isinstance(identifier, BroadbandIdentifier)
        if broadband:
            yield                          # the tone identification's analysis is quick
        if measured.uncertainty > measured.limit:
            self._plant.put_in_force(None, [])
            self._gate.refuse(f"identification failed: {measured.what} "
                              f"{100 * measured.uncertainty:.0f} % > "
                              f"{100 * measured.limit:.0f} % (a disturbance next to a "
                              "tone?); control stays off")
            return
        lines = measured.lines
        self._plant.lines_hz = np.array([line.frequency_hz for line in lines])
        if broadband and self._follower.acquires:
            self._follower.acquire(lines)
        yield from self._engagement.engage(self.tones, measured.response, broadband)
