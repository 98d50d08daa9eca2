"""The whole notch controller, without ROS: canceller, identification, bounds and sequencing.

:class:`NotchSupervisor` is what the ``notch_controller`` node runs and what the core
closed loop (:mod:`hexapod_vibration.core.sim.closed_loop`) runs, so that both take exactly
the same steps. Per sample it removes the DC from the raw accelerations (m/s^2), steps the
Adaptive Notch Canceller (:mod:`~hexapod_vibration.core.control.notch`) and, when one is
running, the plant identification, and returns the command (N). Between samples it takes
parameter changes as a checked set: :meth:`NotchSupervisor.check` refuses a set with the
reason and changes nothing, :meth:`NotchSupervisor.apply` applies a set that passed (the
node's on-set and post-set parameter callbacks).

The supervisor is a facade over collaborators with one job each
(:mod:`hexapod_vibration.core.control.supervisor`): the settings (generated from
``parameter_specs``) and their planning, the sample clock, the plant identification and
what it found, the rate policy (P, the bound on ``mu``, its clamp, per-tone rates and the
predicted sensitivity), the control gate (refused or faded out, with the reason), the safety
monitor (divergence guard, line offset, output fade), the tone follower (reference,
acquisition, tracking, retuning, the sweep's type-2 update) and the event log. The paper
leaves "finding the adaptation rate coefficient" to the user; here the supervisor finds it.

Missing samples (a gap in the indices) move the phases on as if the samples had been
there (:meth:`AdaptiveNotchCanceller.advance`); a gap during an identification restarts it.

What the supervisor decides and the node must tell (log lines, a ``mu`` it lowered that
the ROS parameter must mirror) is queued as :class:`SupervisorEvent` for
:meth:`NotchSupervisor.drain_events`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from typing import Any

import numpy as np

from hexapod_vibration.contract import SAMPLE_RATE_HZ, STRUT_COUNT
from hexapod_vibration.core.control import mu_policy, sensitivity
from hexapod_vibration.core.control.filters import DCBlocker
from hexapod_vibration.core.control.held_inputs import HeldRow
from hexapod_vibration.core.control.notch import FADE_S, AdaptiveNotchCanceller
from hexapod_vibration.core.control.notch_weights import validate_mu
from hexapod_vibration.core.control.plant_identification import (
    DisturbanceSpectrum,
    PlantFrequencyResponse,
)
from hexapod_vibration.core.control.supervisor.analysis_jobs import JobRunner, WaitingJobs
from hexapod_vibration.core.control.supervisor.background_choice import BackgroundChoice
from hexapod_vibration.core.control.supervisor.config import NotchConfig, Settings
from hexapod_vibration.core.control.supervisor.events import EventLog, SupervisorEvent
from hexapod_vibration.core.control.supervisor.fader import OutputFader
from hexapod_vibration.core.control.supervisor.gate import ControlGate
from hexapod_vibration.core.control.supervisor.identification import PlantIdentification
from hexapod_vibration.core.control.supervisor.parts import SupervisorParts
from hexapod_vibration.core.control.supervisor.planning import (
    bank_frequencies,
)
from hexapod_vibration.core.control.supervisor.plant_knowledge import PlantKnowledge
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy
from hexapod_vibration.core.control.supervisor.safety import SafetyMonitor
from hexapod_vibration.core.control.supervisor.sample_clock import GapReport, SampleClock
from hexapod_vibration.core.control.supervisor.settings_change import SettingsChange
from hexapod_vibration.core.control.supervisor.status_report import StatusReport
from hexapod_vibration.core.control.supervisor.tone_follower import ToneFollower

__all__ = ["NotchConfig", "NotchSupervisor", "SupervisorEvent"]


def _initial_canceller(config: NotchConfig, tones: list[float],
                       settings: Settings) -> AdaptiveNotchCanceller:
    """The canceller of the start-up settings at the oscillators ``tones`` (Hz), output off.

    Raw (the paper as printed, P = I) adapts at once; the normalised modes wait for the
    identification to give them their coefficients.
    """
    raw = config.adaptation == "raw"
    canceller = AdaptiveNotchCanceller(settings.channels, tones if raw else [], settings.fs,
                                       validate_mu(config.mu))
    if not raw:
        canceller.set_tone_frequencies(tones, ramp_samples=0)
    canceller.set_enabled(False, ramp_samples=0)
    canceller.set_weight_limit(config.weight_limit_n)
    canceller.set_update_lowpass(settings.update_lowpass_hz)
    return canceller


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
        analysis_worker: where the heavy computations of an identification's analysis run
            (:mod:`~hexapod_vibration.core.control.supervisor.analysis_jobs`), e.g. a process
            beside a realtime loop; None: on the calling thread, one piece per sample (the
            lockstep schedule).
    """

    def __init__(self, config: NotchConfig, sample_rate_hz: float = SAMPLE_RATE_HZ,
                 channels: int = STRUT_COUNT,
                 output_weights: np.ndarray | None = None,
                 analysis_worker: Executor | None = None) -> None:
        """Build the canceller and the DC blocker; identification waits for the first sample."""
        self.fs = float(sample_rate_hz)
        self.channels = int(channels)
        self.output_weights = None if output_weights is None else np.asarray(output_weights, float)
        settings = self._settings = Settings(config, self.fs, self.channels)
        events = self._events = EventLog()
        tones = bank_frequencies(config.tone_frequencies_hz, config.harmonics).tolist()
        canceller = self.canceller = _initial_canceller(config, tones, settings)
        self.dc_blocker = DCBlocker(self.channels, self.fs, config.dc_cutoff_hz)
        self._command = np.zeros(self.channels)
        self._clock, self._gaps = SampleClock(), GapReport(int(round(sample_rate_hz)))
        self._plant = PlantKnowledge()
        self._gate = ControlGate(settings, canceller, events)
        jobs = JobRunner(analysis_worker)
        self._rates = RatePolicy(settings, canceller, self._plant, events, self.output_weights,
                                 WaitingJobs(jobs))
        self._fader = OutputFader(canceller, self.fs)
        self.safety = SafetyMonitor(settings, canceller, self._plant, self._rates, self._gate,
                                    self._fader, events, tones)
        """Never worse than off (guard, line offset, weight clamps)."""
        self.follower = ToneFollower(settings, canceller, self.safety.guard, self._plant,
                                     self._rates, events)
        """The moving tones (reference, tracking, acquisition)."""
        parts = SupervisorParts(settings, canceller, self._clock, self._plant, self._rates,
                                self._gate, self.safety, self.follower, events)
        self.identification = PlantIdentification(parts, jobs)
        """The plant's identification (running, its span)."""
        self._choice = BackgroundChoice(self._rates, canceller, jobs, events)
        self._changes = SettingsChange(parts, self.identification, self._choice)
        self._report = StatusReport(parts, self.identification)
        first = {"mu": config.mu, "tone_frequencies_hz": list(config.tone_frequencies_hz),
                 "adaptation": config.adaptation, "harmonics": config.harmonics}
        self._rates.bound = self._changes.plan(first).bound
        self.follower.rebuild()
        if config.adaptation == "raw" or not config.auto_identify:
            canceller.set_enabled(config.enabled, ramp_samples=0)
            self._gate.warn_if_blind()

    # ------------------------------------------------------------------ settings
    @property
    def config(self) -> NotchConfig:
        """The settings in force."""
        return self._settings.config

    def check(self, changes: Mapping[str, Any]) -> None:
        """Check a set of changes (parameter name -> value) as a whole; change nothing.

        Raises KeyError (not a notch setting) or ValueError (the reason, one line).
        """
        self._changes.plan(changes)

    def apply(self, changes: Mapping[str, Any]) -> None:
        """Apply a set of changes that :meth:`check` accepted (:class:`SettingsChange`).

        Raises:
            KeyError, ValueError: refused (nothing changed), as :meth:`check` would say.
        """
        self._changes.apply(changes)

    def serve_while_waiting(self, idle: Callable[[], None] | None) -> None:
        """Run a setting change's heavy computations on the analysis worker, ``idle`` meanwhile.

        A change of tones or mode while G(f) is known needs its Nyquist limit (~0.6 s) when
        it is checked: with an analysis worker and ``idle`` (the node serving its 1 kHz loop
        for a moment), the caller waits for it without stalling that loop, and the mu
        policy's choice after the apply is made on the worker while the loop runs
        (:class:`BackgroundChoice`). None (or no worker): inline.
        """
        self._rates.waits.serve_with(idle)

    def start_identification(self, tones: list[float] | None = None) -> str:
        """Measure G at ``tones`` (Hz; None: the canceller's) from the next sample, frozen.

        Returns the run's one-line description; ValueError if there are no tones.
        """
        return self.identification.start(tones, self._clock.last + 1)

    def fade_out(self, reason: str, fade_s: float = FADE_S, mu_fall_s: float = 0.0) -> None:
        """Fade control out over ``fade_s`` (s), after mu falls to 0 over ``mu_fall_s`` (s).

        ``reason`` (one line) is reported and held as the refusal (``SafetyMonitor``).
        """
        self.safety.fade_out(reason, fade_s, mu_fall_s)

    # ------------------------------------------------------------------ loop
    def reset_run(self, first_index: int) -> None:
        """A new run of the loop starts at ``first_index`` (a restarted driver).

        The sample sequence restarts there and the DC blocker forgets the old run's
        accelerations; the identified plant, the coefficients and the weights are kept (the
        plant is the same); an identification that was running starts again.
        """
        self._clock.restart_at(first_index)
        self.dc_blocker.reset()
        self.identification.held.clear()
        self.safety.feed.restart()
        self._gate.new_run(first_index)
        self._events.add("warn", f"new run of the loop from sample {first_index}: sequence "
                                 "restarted, identification and weights kept")
        if self.identification.running:
            self.identification.restart(int(first_index))

    def step(self, index: int | None, accel_m_s2: np.ndarray) -> np.ndarray | None:
        """Take the raw accelerations of sample ``index``; the command (N) for that sample.

        Args:
            index: the loop's sample index (None: the one after the last one taken).
            accel_m_s2: (C,) raw accelerations, gravity included (m/s^2), finite.

        Returns:
            (C,) command forces (N), a buffer reused by the next call; None if the sample
            is not after the last one taken (a duplicate or out of order: not used).
        """
        clock = self._clock
        index = clock.last + 1 if index is None else int(index)
        gap = clock.take(index)
        if gap is None:
            return None
        if gap:
            self._missed(index, gap)
        self.identification.start_when_due(index, gap)
        error = self.dc_blocker.step(accel_m_s2)
        canceller, identification = self.canceller, self.identification
        clamped = canceller.clamped_samples
        command = canceller.step(error, out=self._command)
        if canceller.clamped_samples != clamped:
            self.safety.clamps.clamped(index)
        running = identification.identifier is not None
        if self._settings.config.divergence_guard:
            self.safety.step(index, clock.first, error, running, self.follower.active)
        if self._fader.falling:
            self._fader.step()
        if self.follower.active:
            self.follower.step(index, error, running)
        if running or identification.analysis is not None:
            identification.step(error, command)
        if self._choice.running:
            if identification.busy:
                self._choice.cancel()           # its analysis chooses again
            else:
                self._choice.step()
        return command

    def observe(self, index: int, accel_m_s2: np.ndarray) -> None:
        """A sample received but skipped for a newer one: to the identification and guard.

        The guard measures what the platform did, so a sample the loop skipped still counts
        in its block (a block with samples missing is dropped, see ``DivergenceGuard.step``).
        """
        clock = self._clock
        if not clock.observe(index):
            return
        error = self.dc_blocker.step(accel_m_s2)
        self.identification.observe(int(index), error)
        if self._settings.config.divergence_guard and clock.first >= 0:
            self.safety.step(int(index), clock.first, error, self.identification.running,
                             self.follower.active)

    def note_held(self, rows: Sequence[HeldRow], covered: int) -> None:
        """The driver's held commands (``/pph/notch_held``; ``core/control/held_inputs``)."""
        self.identification.held.add(rows, covered)

    def note_stand_ins(self, rows: Sequence[tuple[int, int, int]], covered: int,
                       delay_samples: int) -> None:
        """The driver's stand-ins (``/pph/stand_ins``; ``core/control/guard_feed``).

        ``delay_samples``: the driver's command delay (due sample j is applied at j + d).
        A run of the watchdog's (with the platform's settling) in a running identification's
        record starts it again after them (``supervisor/stall_restart``).
        """
        for first, last in self.safety.feed.note(rows, covered, delay_samples):
            self.identification.stalled(first, last)

    def _missed(self, index: int, gap: int) -> None:
        """``gap`` samples before ``index`` never came: left out, the phases move on.

        A running identification leaves them out of its record (it is refused only if too
        many are missing). Reported at most once per second of samples, with the count
        since the last report (``missed_samples`` on /diagnostics counts every one).
        """
        self.canceller.advance(gap)
        self.identification.skip(index - gap, gap)
        self._gaps.add(index, gap, self._events)

    # ------------------------------------------------------------------ moving tones
    @property
    def tone_estimates_hz(self) -> np.ndarray:
        """(T,) the frequency (Hz) each configured tone's oscillator runs at now."""
        return self.follower.fundamentals_hz.copy()

    def set_reference_frequency(self, frequency_hz: float, index: int | None = None) -> None:
        """Take a tachometer value (Hz) that belongs to loop sample ``index``.

        With ``reference_harmonics`` set, tone k runs at order_k x the reference while the
        value is at most ``reference_timeout_s`` old; a value that is not finite and > 0 is
        ignored (and reported once). ``index`` None: the last sample taken.
        """
        self.follower.reference.set(frequency_hz, self._clock.last if index is None
                                    else int(index))

    # ------------------------------------------------------------------ reporting
    @property
    def state(self) -> str:
        """One of :class:`NotchState`'s names."""
        return self._report.state()

    @property
    def guard_state(self) -> str:
        """The guard's state: disabled, referencing, watching, backed_off or off."""
        return self._report.guard_state()

    def status(self) -> dict[str, Any]:
        """The controller's state as plain values, for ``/diagnostics`` (:class:`StatusReport`)."""
        return self._report.values()

    def drain_events(self) -> Sequence[SupervisorEvent]:
        """The events since the last call, oldest first (and forget them)."""
        return self._events.drain()

    @property
    def last_sample(self) -> int:
        """The last sample taken (-1 before any)."""
        return self._clock.last

    @property
    def counters(self) -> dict[str, int]:
        """Samples missing (``gaps``, ``missed_samples``) and not used (``duplicates``)."""
        return self._clock.counters

    @property
    def bound(self) -> float:
        """The stability bound on ``mu`` in force."""
        return self._rates.bound

    @property
    def plant_response(self) -> np.ndarray | None:
        """Identified G (T, C, C) at the oscillators in force, None until identified."""
        return self._plant.response

    @plant_response.setter
    def plant_response(self, response: np.ndarray | None) -> None:
        """A G (T, C, C) known without identification (e.g. a benchmark's)."""
        self._plant.response = response

    @property
    def plant_frequency_response(self) -> PlantFrequencyResponse | None:
        """G(f) of the last identification if it was broadband, else None."""
        return self._plant.frequency_response

    @plant_frequency_response.setter
    def plant_frequency_response(self, response: PlantFrequencyResponse | None) -> None:
        """A G(f) known without identification (e.g. a test's exact one)."""
        self._plant.frequency_response = response

    @property
    def disturbance_spectrum(self) -> DisturbanceSpectrum | None:
        """The disturbance's spectrum the last broadband identification measured."""
        return self._plant.disturbance

    @property
    def mu_choice(self) -> mu_policy.MuChoice | None:
        """The mu policy's per-tone rates after a broadband identification."""
        return self._rates.choice

    @property
    def sensitivity(self) -> sensitivity.SensitivityPrediction | None:
        """The predicted |S(f)| with the policy's rates, after a broadband identification."""
        return self._rates.sensitivity
