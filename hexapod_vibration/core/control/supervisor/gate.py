"""Whether control may run: held off (and why) or on as set, and since which sample.

Control is held off when the identification gave nothing usable (:attr:`Hold.REFUSED`: no
usable G, no stable rate) or when the safety monitor faded it out
(:attr:`Hold.FADED_OUT`, :mod:`.safety`); the reason is the one line ``refusal`` on
``/diagnostics``. While held, switching control on changes nothing but the setting. The
hold ends with the next accepted identification, or, after a fade-out, with new settings.
"""

from __future__ import annotations

from enum import StrEnum

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.notch import AdaptiveNotchCanceller
from hexapod_vibration.core.control.supervisor.config import Settings
from hexapod_vibration.core.control.supervisor.events import EventLog

BLIND_CONTROL = ("control on but not adapting: the plant at the tones is not identified and "
                 "auto_identify is false; call the ~/identify service (std_srvs/Trigger) or "
                 "set auto_identify true")
"""What a normalised mode switched on without an identified plant says."""


class Hold(StrEnum):
    """Why control is held off (``NONE``: it is not)."""

    NONE = "none"
    REFUSED = "refused"
    """The identification gave no usable coefficients or no stable rate."""
    FADED_OUT = "faded_out"
    """The safety monitor faded control out (worse than off, or a line off the notch)."""


class ControlGate:
    """The hold and its reason, the switching of the canceller's output, since when it is on.

    Args:
        settings: the settings in force (``enabled``, ``ramp_s``).
        canceller: the canceller switched on and off.
        events: where refusals and switching are reported.
    """

    def __init__(self, settings: Settings, canceller: AdaptiveNotchCanceller,
                 events: EventLog) -> None:
        """Not held; control not on yet."""
        self._settings = settings
        self._canceller = canceller
        self._events = events
        self.hold = Hold.NONE
        self.reason = ""
        """Why control is held off (one line; "" when it is not)."""
        self.enabled_since_sample = -1
        """The sample control was last switched on from (-1: it is off)."""

    @property
    def held(self) -> bool:
        """True while control is held off."""
        return self.hold is not Hold.NONE

    def refuse(self, reason: str) -> None:
        """Keep control off (frozen, faded out smoothly) and say why (error)."""
        self.hold, self.reason = Hold.REFUSED, reason
        self._canceller.set_frozen(True)
        self._switch_off()
        self._events.add("error", reason)

    def _switch_off(self) -> None:
        """The output fades to 0 along the smooth curve (``Settings.fade_out_samples``)."""
        self._canceller.set_enabled(False, self._settings.fade_out_samples, smooth=True)

    def faded_out(self, reason: str) -> None:
        """The safety monitor faded control out: held off, and why (error)."""
        self.hold, self.reason = Hold.FADED_OUT, reason
        self._events.add("error", reason)

    def release(self) -> None:
        """No longer held (control may run again)."""
        self.hold, self.reason = Hold.NONE, ""

    def resume(self) -> None:
        """Adapt again, and the output as set (ramped on, or faded out smoothly)."""
        self._canceller.set_frozen(False)
        self._set_output(self._settings.config.enabled)

    def _set_output(self, flag: bool) -> None:
        """The output on (ramped over ``ramp_s``) or off (the smooth fade)."""
        if flag:
            self._canceller.set_enabled(True, self._settings.ramp_samples)
        else:
            self._switch_off()

    def switch(self, flag: bool, identifying: bool, next_sample: int) -> None:
        """Control switched on or off from ``next_sample``.

        The output waits while the plant is identified, and stays off while held; switched
        off it fades out along the smooth curve (``Settings.fade_out_samples``), as the
        safety monitor's fades do.
        """
        if not identifying and not (flag and self.held):
            self._set_output(flag)
        self.enabled_since_sample = next_sample if flag else -1
        self._events.add("info", f"control {'on' if flag else 'off'} from sample {next_sample}")
        if flag:
            self.warn_if_blind(identifying)

    def blind(self, identifying: bool = False) -> bool:
        """Control is set on, cannot adapt and will not learn how by itself.

        The normalised modes adapt once the plant at their tones is identified; with
        ``auto_identify`` false no identification starts unless asked for (``identifying``:
        one asked for is under way, so control is not blind).
        """
        config = self._settings.config
        return (config.enabled and not identifying and not config.auto_identify
                and not self._canceller.adapts)

    def warn_if_blind(self, identifying: bool = False) -> None:
        """Say so (warn, :data:`BLIND_CONTROL`) if control is :meth:`blind`."""
        if self.blind(identifying):
            self._events.add("warn", BLIND_CONTROL)

    def started(self, next_sample: int) -> None:
        """An identification put control in force: on from ``next_sample`` if set so."""
        if self._settings.config.enabled and self.enabled_since_sample < 0:
            self.enabled_since_sample = next_sample

    def new_run(self, first_index: int) -> None:
        """A new run of the loop: control (if on and not held) is on from its first sample."""
        if self._settings.config.enabled and not self.held:
            self.enabled_since_sample = int(first_index)

    def state(self, identifying: bool, known: bool) -> NotchState:
        """The controller's state (``known``: the plant at the oscillators is identified).

        Identifying, refused, adapting (on with a known plant), enabled or disabled.
        """
        if identifying:
            return NotchState.IDENTIFYING
        if self.held:
            return NotchState.REFUSED
        if self._canceller.enabled and known:
            return NotchState.ADAPTING
        return NotchState.ENABLED if self._canceller.enabled else NotchState.DISABLED
