"""Never worse than off: the divergence guard, the line-offset check, the anti-windup count.

- The divergence guard (:mod:`~hexapod_vibration.core.control.divergence_guard`) records
  the error's band levels while control is off and nothing is injected (from
  :data:`GUARD_SETTLE_S` after the first sample and after an identification), and under
  control lowers ``mu`` (:attr:`SafetyLevel.BACKED_OFF`), then fades out
  (:attr:`SafetyLevel.OFF`), when a band rises above that level.
- With the tones fixed (no tracking, no tachometer), the line under each tone is located
  from the weights' turning (:mod:`~hexapod_vibration.core.control.line_offset`); a line
  where the prediction gives control less than ``guard_margin_db`` of reduction (a
  mismatch or a drift beyond the notch's width) fades control out before any band rises:
  mu falls to 0 over :data:`LINE_OFFSET_MU_RAMP_S`, then the output fades over
  :data:`LINE_OFFSET_FADE_S` (:mod:`.fader`).
- The canceller clamps its weights to ``weight_limit_n`` after every update (anti-windup);
  the clamps are counted and reported once a second, and a fade-out while they hold the
  weights at the limit says so (:mod:`.weight_clamps`).

Control faded out stays off (:class:`~.gate.ControlGate` holds it) until the settings
change or a new identification succeeds (:meth:`SafetyMonitor.restart`).
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from typing import Any

import numpy as np

from hexapod_vibration.core.control.divergence_guard import (
    GUARD_BACKED_OFF,
    GUARD_DISABLED,
    GUARD_OFF,
    GUARD_REFERENCING,
    GUARD_WATCHING,
    MU_DIVISOR,
    DivergenceGuard,
    GuardVerdict,
)
from hexapod_vibration.core.control.guard_feed import GuardFeed
from hexapod_vibration.core.control.line_offset import MIN_COHERENCE, LineOffsetMonitor
from hexapod_vibration.core.control.notch import FADE_S, AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.events import EventLog
from hexapod_vibration.core.control.supervisor.fader import OutputFader
from hexapod_vibration.core.control.supervisor.gate import ControlGate
from hexapod_vibration.core.control.supervisor.plant_knowledge import (
    PlantKnowledge,
    coefficients_in_force,
)
from hexapod_vibration.core.control.supervisor.rate_policy import RatePolicy
from hexapod_vibration.core.control.supervisor.weight_clamps import WeightClamps

GUARD_SETTLE_S = 0.5
"""After the first sample (DC blocker) and after an identification (the excitation's
decay) the guard waits this long before the error counts as the level without control (s)."""
LINE_OFFSET_FADE_S = 5.0
"""Fade (s) of the output when a line is off the notch (nothing runs away there), after
:data:`LINE_OFFSET_MU_RAMP_S`. (Measured on ``drift`` when the weights froze at once, core
loop against its twin, the quiet 44.7-56.2 Hz third octave, worst 1 s block during the
fade: +3.9 dB with 2 s, +3.0 with 3 s, +1.3 with 5 s.)"""
LINE_OFFSET_MU_RAMP_S = 2.0
"""Before that fade, mu falls to 0 over this (s, raised cosine) with the weights still
adapting; then they freeze (:mod:`.fader`). Moving each oscillator to where its weights had
turned over the last 50 ms instead held for one steadily turning line (``drift``) but not
for weights that wander: ``spin_up`` without tracking froze orders 2 and 3 (0.09 and
0.03 N, 2-5 Hz off their lines) onto 60.69 and 95.22 Hz, and the kink put +11 dB into the
quiet 44.7-56.2 Hz band. With mu falling the weights slow down and shrink smoothly (for a
line off the notch, ``|W|`` scales with mu). Core loop against the twin, worst 12 s window
from control-on (Welch 4 s): ``spin_up`` without tracking +2.50 -> +0.44 dB, ``drift``
+0.63 -> +0.35 dB (a 1 s fall: +0.41 / +0.29 dB; over 1 s blocks ``drift`` is +5.2 dB in
44.7-56.2 Hz while mu falls, +4.6 dB in 56-71 Hz before)."""

LINE_GAP_SAMPLES = 20
"""A gap longer than this (samples neither stepped nor observed: lost on the way) restarts the
line monitor: its blocks count samples, which a gap stretches in time. The samples marked
for a run of the driver's watchdog (:data:`~hexapod_vibration.core.control.guard_feed.
WATCHDOG_SETTLE_SAMPLES`) restart it too: the weights re-converge after the force came back,
and they turn as they do (``single_tone_harmonic`` in realtime, both controllers stopped
for 350 ms under control: the 80 Hz weights turned coherently at -0.30 and -0.35 Hz
0.3-0.44 s later, in two runs of two, and the check faded control out)."""


class SafetyLevel(StrEnum):
    """How far the safety monitor backed control off (its values are the guard's states)."""

    WATCHING = GUARD_WATCHING
    BACKED_OFF = GUARD_BACKED_OFF
    """The guard lowered mu at least once."""
    OFF = GUARD_OFF
    """Control faded out."""


class SafetyMonitor:
    """Watches the error under control; lowers mu, fades out; counts the weights' clamps.

    Args:
        settings: the settings in force.
        canceller: the canceller watched.
        plant: what the identifications found (the response in force, the lines).
        rates: the rate policy (lowers mu; the predicted sensitivity).
        gate: holds control off after a fade-out.
        fader: fades the output out.
        events: where the actions are reported.
        tones: the oscillators (Hz) at start-up.
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 plant: PlantKnowledge, rates: RatePolicy, gate: ControlGate,
                 fader: OutputFader, events: EventLog, tones: list[float]) -> None:
        """The guard on ``tones`` with the margin in force; nothing recorded yet."""
        self._settings, self._canceller = settings, canceller
        self._plant, self._rates, self._gate = plant, rates, gate
        self._fader, self._events = fader, events
        self.guard = DivergenceGuard(settings.channels, settings.fs, tones,
                                     settings.config.guard_margin_db)
        self.feed = GuardFeed(self.guard)
        """The guard's samples, held for a realtime driver's stand-in reports."""
        self.action = ""
        """The last action and why (``guard_action`` on /diagnostics)."""
        self.line_monitor = LineOffsetMonitor(len(tones), settings.fs)
        self.level = SafetyLevel.WATCHING
        self.clamps = WeightClamps(settings, canceller, events)
        """The weights' clamps (anti-windup): counted, said, held at the limit or not."""
        self._quiet_from_sample = -1
        self._last_sample = -1

    @property
    def given_up(self) -> bool:
        """True once control was faded out (until :meth:`restart`)."""
        return self.level is SafetyLevel.OFF

    def step(self, n: int, first_sample: int, error: np.ndarray, identifying: bool,
             following: bool) -> None:
        """Feed sample ``n``'s error (C,) (m/s^2) to the guard and the line monitor; act.

        ``identifying``: an identification injects its excitation; ``following``: the
        tones move (tracking or a reference: no line-offset check).
        """
        canceller = self._canceller
        quiet = (not identifying and n >= self._quiet_from_sample
                 and n - first_sample >= GUARD_SETTLE_S * self._settings.fs)
        off = not canceller.enabled and canceller.output_gain == 0.0
        controlling = (canceller.enabled and canceller.output_gain == 1.0
                       and not canceller.frozen and not identifying
                       and coefficients_in_force(self._plant, canceller)
                       and self.level is not SafetyLevel.OFF)
        feed, watchdog_samples = self.feed, self.feed.watchdog_samples
        for verdict, sample in feed.step(error, quiet and off, controlling, n):
            if self.level is not SafetyLevel.OFF:
                self._judged(verdict, sample)
        gap = self._last_sample >= 0 and n - self._last_sample > LINE_GAP_SAMPLES + 1
        self._last_sample = n
        if (gap or feed.watchdog_samples != watchdog_samples) and self.line_monitor.started:
            self.line_monitor.reset()
        self._check_lines(controlling and not following, n)

    def _judged(self, verdict: GuardVerdict, n: int) -> None:
        """A judged block ending at sample ``n``: the clamps' share of it; the guard's action."""
        self.clamps.judged(n, self.guard.block)
        if verdict.action is not None:
            self._act(verdict, n)

    def _act(self, verdict: GuardVerdict, n: int) -> None:
        """Lower mu, or fade out; say what and why."""
        self.action = f"{verdict.text} at sample {n}"
        if verdict.action == "lower_mu":
            mu = self._canceller.mu / MU_DIVISOR
            self.level = SafetyLevel.BACKED_OFF
            self._rates.set_mu(mu, f"divergence guard: {self.action}: mu lowered to {mu:.4g}")
            return
        self.fade_out(f"divergence guard: {self.action}: control faded out "
                      "(worse than off at any rate tried)")

    def _check_lines(self, watching: bool, n: int) -> None:
        """Fixed tones: locate each tone's line from the weights; fade out off the notch.

        The line sits ``offset_hz`` from its tone; the predicted change of the error there
        (the same |S(f)| the mu policy bounds: the output's, else the worst strut's) says
        what control does to it. Less than ``guard_margin_db`` of reduction for a line the
        weights follow steadily (coherence >= MIN_COHERENCE) means the canceller's model
        (the line at the tone) is wrong by more than its notch is wide: control can gain
        at most the margin and a moving line beats against it (``drift``, without this:
        +7 dB in 44.7-56.2 Hz for 0.5 s and the 79 Hz third octave +5.7 dB before the
        guard's band levels saw it), so it fades out, saying where the line is. Only a tone
        with a disturbance line in its band (fitted by the identification) counts: weights
        driven by broadband noise alone turn too, at about the notch's width, where a fast
        notch may reduce little.
        """
        monitor, canceller = self.line_monitor, self._canceller
        prediction = self._rates.sensitivity
        if not watching or prediction is None:
            if monitor.started:
                monitor.reset()
            return
        if monitor.tones != canceller.n_tones:
            self.line_monitor = monitor = LineOffsetMonitor(canceller.n_tones,
                                                            self._settings.fs)
        if not monitor.step_from(canceller) or not monitor.ready:
            return
        tones = canceller.tone_frequencies_hz
        lines = tones + monitor.offset_hz
        change_db = prediction.db_at(lines)
        margin_db = self._settings.config.guard_margin_db
        has_line = np.any(np.abs(self._plant.lines_hz[None, :] - tones[:, None])
                          <= self.guard.half_width_hz, axis=1)
        steady = monitor.coherence >= MIN_COHERENCE
        bad = has_line & steady & (change_db > -margin_db)
        if not np.any(bad):
            return
        k = int(np.flatnonzero(bad)[0])
        self.action = (
            f"tone {tones[k]:g} Hz: its line is at {lines[k]:.2f} Hz (the weights turn at "
            f"{monitor.offset_hz[k]:+.2f} Hz), where control is predicted to change it by "
            f"{change_db[k]:+.1f} dB (less than guard_margin_db {margin_db:g} dB of "
            f"reduction) at sample {n}")
        self.fade_out(f"line off the notch: {self.action}: control faded out (mu "
                      f"to 0 over {LINE_OFFSET_MU_RAMP_S:g} s, then the output over "
                      f"{LINE_OFFSET_FADE_S:g} s; frequency_tracking follows a line that is "
                      "not where it was told)", LINE_OFFSET_FADE_S, LINE_OFFSET_MU_RAMP_S)

    def fade_out(self, reason: str, fade_s: float = FADE_S, mu_fall_s: float = 0.0) -> None:
        """Fade control out (``fade_s`` s, after mu falls over ``mu_fall_s`` s); say why.

        Control stays off until the settings change or a new identification succeeds.
        """
        self.level = SafetyLevel.OFF
        self._fader.fade_out(fade_s, mu_fall_s)
        self._gate.faded_out(reason + self.clamps.note())

    def apply(self, changes: Mapping[str, Any], tones: list[float] | None) -> None:
        """New settings: ``weight_limit_n``, ``guard_margin_db``, the oscillators.

        New oscillators ``tones`` (Hz; None: unchanged) get new bands (the reference starts
        again).
        """
        if "weight_limit_n" in changes:
            self._canceller.set_weight_limit(float(changes["weight_limit_n"]))
        if "guard_margin_db" in changes:
            self.guard.margin_db = float(changes["guard_margin_db"])
        if tones is not None:
            self.feed.clear()
            self.guard.set_tones(tones)

    def retry(self, identifying: bool) -> None:
        """New settings after a fade-out: it no longer holds, control may try again.

        The output comes back (as set) unless an identification runs or nothing adapts
        (:func:`coefficients_in_force`).
        """
        if not self.given_up:
            return
        self.restart()
        self._gate.release()
        if not identifying and coefficients_in_force(self._plant, self._canceller):
            self._gate.resume()

    def restart(self) -> None:
        """New coefficients or settings: the actions start again from watching."""
        self._fader.end()
        self.feed.clear()
        self.guard.restart()
        self.clamps.restart()
        self.level = SafetyLevel.WATCHING

    def quiet_after(self, sample: int) -> None:
        """An identification ended at ``sample``: its excitation decays before recording."""
        self._quiet_from_sample = sample + int(round(GUARD_SETTLE_S * self._settings.fs))

    def state(self, enabled: bool, adapting: bool) -> str:
        """The guard's state: disabled, referencing, watching, backed_off or off."""
        if not enabled:
            return GUARD_DISABLED
        if self.level is SafetyLevel.OFF:
            return GUARD_OFF
        return self.level.value if adapting else GUARD_REFERENCING

    def status(self, state: str) -> dict[str, Any]:
        """The guard's ``state``, its last action, reference, clamps and the lines located."""
        values = {"guard": state, "guard_action": self.action,
                  "guard_reference_blocks": self.guard.reference_blocks,
                  "guard_blocks_with_gaps": self.guard.blocks_with_gaps,
                  "guard_blocks_with_stand_ins": self.guard.blocks_with_stand_ins,
                  "weight_clamps": self.clamps.count,
                  "weights_held_at_limit": self.clamps.held}
        monitor = self.line_monitor
        if monitor.ready:
            values.update({"line_offset_hz": np.round(monitor.offset_hz, 4).tolist(),
                           "line_coherence": np.round(monitor.coherence, 3).tolist()})
        return values
