"""The CPU budget of a node's 1 kHz loop: CPU time per sample, per stage of the loop.

A node's loop runs in one thread. At the end of each stage (waiting for a message, taking
it, decoding it, the control law or the plant, publishing, reporting) it calls
``LoopCostMeter.lap`` with the stage's index: the thread's CPU time since the previous
lap (``time.thread_time``, user + system: a system call, 0.7 us on the project's 2-core AMD
machine) is added to that stage. Once per loop sample it calls
:meth:`LoopCostMeter.count`. Every :data:`WINDOW_SAMPLES` samples the meter closes a
window: per stage, the main thread and the whole process (every thread: the DDS
transport's receive and event threads too), the CPU time per sample in us.

The stages are timed on one loop sample in :data:`STAGE_STRIDE_SAMPLES` (a lap on the
others is a no-op): the composed graph laps about 20 times a sample, and timing every lap
cost 5-7 % of its lockstep rate. A stage's figure is its mean over the timed samples of the
window; the main thread's and the process's are exact (their clocks are read once a
window).

Nodes composed into one process and thread share one meter (stage names are per node), so
the budget is always that of a process. No ROS import: the nodes publish :meth:`report` on
``/diagnostics``; the benchmark reads it from there.
"""

from __future__ import annotations

import time
from collections.abc import Callable

WINDOW_SAMPLES = 1000
"""Samples per reporting window (1 s of sim time at 1 kHz)."""
KEY_PREFIX = "cpu_us_per_sample "
"""Prefix of the ``/diagnostics`` keys of :meth:`LoopCostMeter.report`."""
MAIN_THREAD = "main thread"
PROCESS = "process"
OTHER_THREADS = "other threads"
STAGE_STRIDE_SAMPLES = 7
"""Loop samples per timed sample of the stages: a prime, so the timed samples do not alias
with the loops' periodic work (every 10, 100 or 1000 samples)."""


class LoopCostMeter:
    """CPU time (us per sample) of a loop's stages, its thread and its process.

    Args:
        thread_clock: CPU seconds of the calling thread (tests pass a fake clock).
        process_clock: CPU seconds of the whole process.
        stride_samples: The stages are timed on one loop sample in this many (1: every one).

    Attributes:
        lap: ``lap(stage)`` charges the thread's CPU time since the previous lap to
            ``stage`` on a timed sample, and does nothing on the others.
    """

    def __init__(self, thread_clock: Callable[[], float] = time.thread_time,
                 process_clock: Callable[[], float] = time.process_time,
                 stride_samples: int = STAGE_STRIDE_SAMPLES) -> None:
        """No stage yet; the first sample is timed and its first lap measures from now."""
        if stride_samples < 1:
            raise ValueError(f"stride_samples must be >= 1, got {stride_samples}")
        self._thread_clock = thread_clock
        self._process_clock = process_clock
        self._stride = stride_samples
        self.names: list[str] = []
        self._spent: list[float] = []
        self._samples = 0
        self._timed = 0
        self._charge_lap = self._charge     # one bound method: count() tests it by identity
        self.lap: Callable[[int], None] = self._charge_lap
        self._last = thread_clock()
        self._window_start = (0, 0, self._last, process_clock(), [])
        self._window: dict[str, float] = {}
        self._counter: str | None = None

    def stage(self, name: str) -> int:
        """The index of stage ``name`` (registered on first use), for :meth:`lap`."""
        if name not in self.names:
            self.names.append(name)
            self._spent.append(0.0)
        return self.names.index(name)

    def _charge(self, stage: int) -> None:
        """Charge the thread's CPU time since the previous lap to ``stage`` (a timed lap)."""
        now = self._thread_clock()
        self._spent[stage] += now - self._last
        self._last = now

    def counter(self, owner: str) -> Callable[[], None]:
        """The function ``owner`` calls once per loop sample.

        :meth:`count` for the first owner to ask (the process's loop, e.g. the driver of a
        composed graph), a no-op for the others: a sample is counted once per process.
        """
        if self._counter in (None, owner):
            self._counter = owner
            return self.count
        return _no_count

    def count(self) -> None:
        """One loop sample done; closes a window every :data:`WINDOW_SAMPLES` samples.

        Decides whether the next sample is timed; a timed sample after an untimed one
        measures its first lap from here.
        """
        timed = self.lap is self._charge_lap
        self._timed += timed
        self._samples += 1
        if self._samples % self._stride:
            self.lap = _no_lap
        elif not timed:
            self._last = self._thread_clock()
            self.lap = self._charge_lap
        if self._samples - self._window_start[0] >= WINDOW_SAMPLES:
            self._close_window()

    def _close_window(self) -> None:
        samples0, timed0, thread0, process0, spent0 = self._window_start
        thread, process = self._thread_clock(), self._process_clock()
        per_sample = 1e6 / (self._samples - samples0)
        per_timed = 1e6 / max(self._timed - timed0, 1)
        spent0 = spent0 + [0.0] * (len(self._spent) - len(spent0))
        window = {name: (spent - before) * per_timed
                  for name, spent, before in zip(self.names, self._spent, spent0, strict=True)}
        window[MAIN_THREAD] = (thread - thread0) * per_sample
        window[PROCESS] = (process - process0) * per_sample
        window[OTHER_THREADS] = window[PROCESS] - window[MAIN_THREAD]
        self._window = window
        self._window_start = (self._samples, self._timed, thread, process, list(self._spent))

    @property
    def samples(self) -> int:
        """Samples counted since the meter was made."""
        return self._samples

    def last_window(self) -> dict[str, float]:
        """CPU us per sample of the last closed window, by stage, thread and process."""
        return dict(self._window)

    def report(self) -> dict[str, float]:
        """:meth:`last_window` as ``/diagnostics`` values (``cpu_us_per_sample <name>``)."""
        return {f"{KEY_PREFIX}{name}": round(value, 2) for name, value in self._window.items()}


def _no_lap(stage: int) -> None:
    """``LoopCostMeter.lap`` on a sample whose stages are not timed."""


def _no_count() -> None:
    """:meth:`LoopCostMeter.counter` of a node whose samples another node counts."""
