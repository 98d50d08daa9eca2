"""The driver's side of the loop without ROS: pair commands with samples, watchdog, statistics.

The driver publishes the sensors of sample ``n`` and applies, over [n, n+1), the commands
of its controllers' streams (notch, pointing). :class:`CommandArbiter` decides which
command of each stream that is:

- **the command delay** ``d`` (``command_delay_samples``): the command answering sample
  ``n`` is applied over [n+d, n+d+1), so a controller has d+1 periods to answer in
  realtime (a pipeline; the loop's delay grows by d samples, which the notch's
  identification measures and its ``loop_delay_samples`` must include). ``d = 0``: the
  answer to sample n is applied over [n, n+1);
- **one command per sample, the first valid one**: a command is refused (and counted by
  reason) if it is malformed (counted by the node, :meth:`CommandArbiter.refuse`), beyond
  the actuator's range, of another run, for a sample not published yet, or for a sample at
  or before the stream's last accepted command (a duplicate, or a late one out of order);
- **pairing** (lockstep): the driver advances once every *waited* stream answered the
  current sample; a stream is waited for while it is expected (``lockstep_controllers``),
  connected (a publisher on the graph, or a recent command) and alive (a command accepted
  within the last ``timeout_samples`` samples, even one for an older sample: a restarted
  controller working through its queue is waited for again at once);
- **forecast** (realtime, a stream that publishes one): when a stream's command for the
  sample due is late, its forecast's row for that sample is applied instead of the held
  command (:meth:`CommandArbiter.forecast`, :mod:`~hexapod_vibration.core.loop.
  forecast_buffer`), counted as ``<stream>_forecast_applied``; the command is still late;
- **watchdog**: a stream whose last accepted command is more than ``timeout_samples``
  samples old, and whose forecast does not cover the sample due, is stale: its force falls
  to zero (over ``fade_samples`` samples, :mod:`~hexapod_vibration.core.loop.stale_fade`,
  from its last command) and rises back the same way when it commands again; until it is
  stale its last command is held (zero-order hold);
- **statistics**: samples, lockstep timeouts and missed samples, realtime late commands,
  offers repeated, the latency from a sample's publication to its notch command and the
  period between publications (wall clock, percentiles over the last minute,
  :mod:`~hexapod_vibration.core.loop.rolling_percentiles`).

Wall-clock times are passed in (seconds, any monotonic origin); nothing here reads a clock
or the ROS graph, so every rule is unit-tested directly (``test/core/test_command_arbiter.py``).
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from hexapod_vibration.contract import STRUT_COUNT
from hexapod_vibration.core.loop.forecast_buffer import ForecastBuffer
from hexapod_vibration.core.loop.rolling_percentiles import RollingPercentiles
from hexapod_vibration.core.loop.signal_ranges import out_of_range
from hexapod_vibration.core.loop.stale_fade import StaleFade

NO_FORCE_N = np.zeros(STRUT_COUNT)
"""Read-only: what a stale stream contributes (N)."""
NO_FORCE_N.flags.writeable = False

PUBLISH_HISTORY = 1024
"""Samples whose publication time is kept for the latency."""


class Refusal(StrEnum):
    """Why a command was not taken."""

    MALFORMED = "malformed"          # undecodable bytes, wrong length, non-finite, bad label
    OUT_OF_RANGE = "out_of_range"    # beyond what the actuator can be asked for
    OTHER_RUN = "other_run"          # answers another run of the driver
    FUTURE = "future"                # for a sample not published yet
    OUT_OF_ORDER = "out_of_order"    # for a sample before the stream's last command
    DUPLICATE = "duplicate"          # a second command for the same sample

    @property
    def invalid(self) -> bool:
        """A refusal that no well-behaved controller causes (duplicates are harmless)."""
        return self is not Refusal.DUPLICATE


@dataclass
class CommandStream:
    """Latest accepted command of one controller and its bookkeeping."""

    name: str
    force_n: np.ndarray = field(default_factory=lambda: np.zeros(STRUT_COUNT))
    """The force applied last (N): the command of sample ``applied``, held while none is due."""
    applied: int = -1
    """Sample index of the command applied last (-1: none yet)."""
    queued: deque = field(default_factory=deque)
    """Accepted commands not applied yet, as (sample index, force (N)), oldest first."""
    sample: int = -1
    """Sample index of the last accepted command (-1: none yet)."""
    accepted_at: int = -1
    """The driver's current sample when that command was accepted."""
    received_s: float = 0.0
    forecast: ForecastBuffer = field(default_factory=ForecastBuffer)
    """The stream's newest forecast (empty unless its controller publishes one)."""
    refused: Counter = field(default_factory=Counter)
    late: int = 0
    stale: bool = True
    stale_events: int = 0
    connected: bool = False
    """A publisher on the graph (looked up every few hundred samples) or a command accepted
    recently: from its first accepted command a joining controller is waited for
    (lockstep) and its late answers counted (realtime)."""
    fade: StaleFade = field(default_factory=StaleFade)
    """The watchdog's ramp: the gain on the stream's force (falls while stale)."""
    stood_in: bool = False
    """Realtime: at the sample closed last the stream was connected and a force it did not
    compute for the due sample went in: a stand-in for its late answer (forecast row or
    held command), the watchdog's ramp or zero force."""

    @property
    def invalid(self) -> int:
        """Refused commands other than duplicates."""
        return sum(n for reason, n in self.refused.items() if reason.invalid)


@dataclass
class LoopStats:
    """Measured loop statistics (wall clock), reported on /diagnostics."""

    samples: int = 0
    timeouts: int = 0
    missed: int = 0
    late_commands: int = 0
    offers_repeated: int = 0
    start_s: float = 0.0
    latencies_ms: RollingPercentiles = field(default_factory=RollingPercentiles)
    periods_ms: RollingPercentiles = field(default_factory=RollingPercentiles)
    last_publish_s: float = 0.0
    paused_at_s: float | None = None
    """Wall time (s) the loop stopped at a breakpoint (None: running)."""


def _apply_due(stream: CommandStream, due: int) -> None:
    """Move ``stream``'s newest queued command for a sample <= ``due`` to its applied one."""
    queued = stream.queued
    while queued and queued[0][0] <= due:
        stream.applied, stream.force_n = queued.popleft()


class CommandArbiter:
    """Which command of each stream the driver applies at its current sample."""

    def __init__(self, streams: Sequence[str], expected: Sequence[str], run: int,
                 limit_n: float, latency_stream: str | None = None,
                 delay_samples: int = 0) -> None:
        """Streams by name, the ones lockstep waits for, the driver's run and force range.

        Args:
            streams: Names of the command streams (e.g. ``("notch", "pointing")``).
            expected: The streams lockstep waits for (a subset of ``streams``).
            run: The driver's run identity; commands of another run are refused.
            limit_n: Largest command magnitude an actuator can be asked for (N).
            latency_stream: The stream whose answers time the loop's latency.
            delay_samples: The command delay d (samples, >= 0): the answer to sample n
                is applied over [n+d, n+d+1).

        Raises:
            ValueError: ``expected`` names a stream not in ``streams``.
        """
        if int(delay_samples) != delay_samples or delay_samples < 0:
            raise ValueError(f"delay_samples must be an integer >= 0, got {delay_samples!r}")
        unknown = set(expected) - set(streams)
        if unknown:
            raise ValueError(f"lockstep_controllers: unknown {sorted(unknown)}, "
                             f"use {tuple(streams)}")
        self.streams = {name: CommandStream(name) for name in streams}
        self.expected = tuple(expected)
        self.run = run
        self.limit_n = limit_n
        self.latency_stream = latency_stream
        self.delay = int(delay_samples)
        self.sample = 0
        """The current sample: published (or about to be), its commands awaited."""
        self.stats = LoopStats()
        self._published_s = np.zeros(PUBLISH_HISTORY)

    # ------------------------------------------------------------------ commands
    def offer(self, name: str, values: np.ndarray, index: int | None, run: int | None,
              now_s: float) -> Refusal | None:
        """Take a decoded command of stream ``name`` (None) or say why not (counted).

        ``index`` None (a publisher without the in-band index) means the current sample;
        ``run`` None (no run label) is accepted from any publisher.
        """
        stream = self.streams[name]
        index = self.sample if index is None else index
        reason = self._check(stream, values, index, run)
        if reason is not None:
            stream.refused[reason] += 1
            return reason
        stream.queued.append((index, np.array(values, dtype=float)))
        stream.connected = True       # a command is proof enough: no wait for the graph
        stream.sample = index
        stream.accepted_at = self.sample
        stream.received_s = now_s
        published = self._published_s[index % PUBLISH_HISTORY]
        if (name == self.latency_stream and self.sample - index < PUBLISH_HISTORY
                and published > 0.0):
            # publication of sample index to reception of its command, late ones included
            self.stats.latencies_ms.add((now_s - published) * 1e3)
        return None

    def _foreign(self, values: np.ndarray, run: int | None) -> Refusal | None:
        """Why forces (N) of a command or forecast cannot be this driver's, or None."""
        if out_of_range(values, self.limit_n):
            return Refusal.OUT_OF_RANGE
        if run is not None and run != self.run:
            return Refusal.OTHER_RUN
        return None

    def _check(self, stream: CommandStream, values: np.ndarray, index: int,
               run: int | None) -> Refusal | None:
        reason = self._foreign(values, run)
        if reason is not None:
            return reason
        if index > self.sample:
            return Refusal.FUTURE
        if index == stream.sample:
            return Refusal.DUPLICATE
        if index < stream.sample:
            return Refusal.OUT_OF_ORDER
        return None

    def forecast(self, name: str, first: int, rows: np.ndarray,
                 run: int | None) -> Refusal | None:
        """Take stream ``name``'s forecast: forces ((K, C) N) for samples ``first``...

        Refused (counted) beyond the actuator's range or of another run; an older forecast
        than the one kept is dropped silently.
        """
        stream = self.streams[name]
        reason = self._foreign(rows, run)
        if reason is None:
            stream.forecast.take(first, rows)
        else:
            stream.refused[reason] += 1
        return reason

    def refuse(self, name: str, reason: Refusal = Refusal.MALFORMED) -> None:
        """Count a message of stream ``name`` refused before it could be offered."""
        self.streams[name].refused[reason] += 1

    # ------------------------------------------------------------------ pairing, watchdog
    def fresh(self, name: str, timeout_samples: int) -> bool:
        """The stream's last command is at most ``timeout_samples`` samples old."""
        stream = self.streams[name]
        return stream.sample >= 0 and self.sample - stream.sample <= timeout_samples

    def refresh_connections(self, publishers: Mapping[str, int], timeout_samples: int) -> None:
        """A stream is connected if the graph shows a publisher or it commanded recently.

        The graph can lag behind the data: a controller that answered the handshake may
        not be listed yet, and it must be waited for all the same.
        """
        for name, stream in self.streams.items():
            stream.connected = (self.alive(name, timeout_samples)
                                or publishers.get(name, 0) > 0)

    def alive(self, name: str, timeout_samples: int) -> bool:
        """A command of the stream was accepted within the last ``timeout_samples`` samples."""
        stream = self.streams[name]
        return stream.accepted_at >= 0 and self.sample - stream.accepted_at <= timeout_samples

    def waited(self, timeout_samples: int) -> list[str]:
        """Expected streams that are connected and alive.

        A controller silent for more than ``timeout_samples`` samples (its process died,
        which discovery may notice only many seconds later) is not waited for any more,
        so the loop runs on without it; it is waited for again once it answers, even a
        sample the loop has passed (a restarted controller catching up with its queue).
        """
        return [n for n in self.expected
                if self.streams[n].connected and self.alive(n, timeout_samples)]

    @property
    def due(self) -> int:
        """The sample whose commands are applied at the current sample (``sample - d``)."""
        return self.sample - self.delay

    def ready(self, timeout_samples: int) -> bool:
        """Lockstep: every waited stream answered the sample due now (:attr:`due`)."""
        return self._answered_since(self.due, timeout_samples)

    def answered(self, timeout_samples: int) -> bool:
        """Every waited stream answered the current sample (no command due: the loop idles)."""
        return self._answered_since(self.sample, timeout_samples)

    def _answered_since(self, sample: int, timeout_samples: int) -> bool:
        return all(self.streams[n].sample >= sample for n in self.waited(timeout_samples))

    def unanswered(self) -> list[str]:
        """Expected streams that did not answer the current sample (the handshake's wait)."""
        return [n for n in self.expected if self.streams[n].sample != self.sample]

    def close_sample(self, lockstep: bool, timeout_samples: int, fade_samples: int = 0
                     ) -> tuple[dict[str, np.ndarray], list[str]]:
        """Count what the current sample lacked; the force of every stream to apply.

        Each stream's command is its answer to the sample due (:attr:`due`); in realtime
        without one, its forecast's row for that sample; else the one applied before, held.
        Lockstep counts the sample as missed if a connected expected stream did not answer
        the sample due; realtime counts every connected stream that did not as late (a
        forecast applied or not). A stale stream's force falls to zero over
        ``fade_samples`` samples (0: at once) and rises back as long once it is fresh.

        Returns:
            ``(forces, newly_stale)``: the force (N) of each stream (its command, forecast
            or held one, times the watchdog's gain), and the streams that went stale at
            this sample.
        """
        due = self.due
        for stream in self.streams.values():
            _apply_due(stream, due)
        answered = {n: s.applied == due or due < 0 for n, s in self.streams.items()}
        if lockstep:
            if any(self.streams[n].connected and not answered[n] for n in self.expected):
                self.stats.missed += 1
        else:
            late = [s for n, s in self.streams.items() if s.connected and not answered[n]]
            for stream in late:
                stream.late += 1
            self.stats.late_commands += bool(late)
        forces, newly_stale = {}, []
        for name, stream in self.streams.items():
            forecast = None if answered[name] or lockstep else stream.forecast.row(due)
            if forecast is not None:
                stream.force_n, stream.applied = forecast, due
                stream.forecast.applied += 1
            stale = forecast is None and not self.fresh(name, timeout_samples)
            gain = stream.fade.step(stale, fade_samples)
            stream.stood_in = (not lockstep and stream.connected
                               and (not answered[name] or gain < 1.0))
            if stale and not stream.stale and stream.sample >= 0:
                stream.stale_events += 1
                newly_stale.append(name)
            stream.stale = stale
            forces[name] = (stream.force_n if gain == 1.0 else NO_FORCE_N if gain == 0.0
                            else gain * stream.force_n)
        return forces, newly_stale

    def advance(self) -> None:
        """The current sample was applied: the next one becomes current."""
        self.sample += 1
        self.stats.samples += 1

    # ------------------------------------------------------------------ statistics
    def published(self, now_s: float) -> None:
        """The current sample's sensors were published (first time) at ``now_s``."""
        self._published_s[self.sample % PUBLISH_HISTORY] = now_s
        stats = self.stats
        if stats.last_publish_s:
            stats.periods_ms.add((now_s - stats.last_publish_s) * 1e3)
        stats.last_publish_s = now_s

    def offered_again(self) -> None:
        """The current sample's sensors were published once more (lockstep re-offer)."""
        self.stats.offers_repeated += 1

    def timed_out(self) -> None:
        """Lockstep gave up waiting for the current sample's commands."""
        self.stats.timeouts += 1

    def pause(self, now_s: float) -> None:
        """The loop stopped at a breakpoint at ``now_s`` (s): its rate leaves the pause out."""
        if self.stats.paused_at_s is None:
            self.stats.paused_at_s = now_s

    def resume(self, now_s: float) -> None:
        """The loop left its breakpoint at ``now_s`` (s): the pause is no period either."""
        stats = self.stats
        if stats.paused_at_s is not None:
            pause_s = now_s - stats.paused_at_s
            stats.start_s += pause_s
            if stats.last_publish_s:
                stats.last_publish_s += pause_s
            stats.paused_at_s = None

    def restart_stats(self, now_s: float) -> None:
        """Start the statistics afresh (after the handshake)."""
        self.stats = LoopStats(start_s=now_s)

    def report(self, now_s: float, lockstep: bool) -> tuple[dict[str, object], bool, str]:
        """Key/values for /diagnostics, whether to warn, and the status message."""
        st = self.stats
        wall = max((now_s if st.paused_at_s is None else st.paused_at_s) - st.start_s, 1e-9)
        lat50, lat99 = st.latencies_ms.percentiles((50, 99))
        per50, per99 = st.periods_ms.percentiles((50, 99))
        # Stale: connected, or sent commands before (a controller that went away).
        stale = [n for n, s in self.streams.items()
                 if s.stale and (s.connected or s.sample >= 0)]
        values: dict[str, object] = {
            "run": self.run, "sample": self.sample, "samples": st.samples,
            "rate_hz": st.samples / wall, "timeouts": st.timeouts,
            "late_commands": st.late_commands,
            "missed_samples": st.missed if lockstep else st.late_commands,
            "offers_repeated": st.offers_repeated,
            "latency_ms_p50": lat50, "latency_ms_p99": lat99,
            "latency_ms_max": st.latencies_ms.maximum(), "period_ms_p50": per50,
            "period_ms_p99": per99, "period_ms_max": st.periods_ms.maximum(),
        }
        for name, s in self.streams.items():
            values.update({f"{name}_last_sample": s.sample, f"{name}_invalid": s.invalid,
                           f"{name}_stale_events": s.stale_events,
                           f"{name}_late": s.late, f"{name}_connected": s.connected,
                           f"{name}_forecast_applied": s.forecast.applied})
            values.update({f"{name}_{reason}": s.refused[reason] for reason in Refusal})
        invalid = any(s.invalid for s in self.streams.values())
        warn = bool(stale or st.timeouts or st.missed or invalid)
        return values, warn, f"stale: {', '.join(stale)}" if stale else "ok"
