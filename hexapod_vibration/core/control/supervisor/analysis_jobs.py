"""The heavy computations of an identification's analysis, run inline or on a worker.

The analysis of a finished identification is a generator run one piece per sample
(:class:`Pieces`). A piece that needs a heavy, pure computation (G(f) from the record, a
Nyquist test, the mu policy) yields a :class:`Job` and is resumed with its result:

- inline (no worker, lockstep): the job runs at once and the piece goes on in the same
  sample, so the schedule (which sample control goes on at) is the one of a plain call;
- on a worker (an :class:`concurrent.futures.Executor`, e.g. a process at normal priority
  beside a realtime loop): the job is submitted and the analysis waits, sample after sample,
  until its result is there; the loop thread keeps its deadline meanwhile.

A worker that breaks (its process died) is given up for good: the job and every later one
run inline, and :meth:`JobRunner.lost_news` says why, once.

A computation that must finish before its caller goes on (a setting change's Nyquist limit,
which decides whether the change is accepted) runs to its end at once
(:func:`run_waiting`): on a worker, the caller serves its loop meanwhile.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator
from concurrent.futures import BrokenExecutor, Executor, Future
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Job:
    """A pure computation ``fn(*args, **kwargs)``: module-level, picklable arguments."""

    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict[str, Any] = field(default_factory=dict)


Analysis = Generator["Job | None", Any, Any]
"""A computation in pieces: yields None to end a piece, a :class:`Job` for its result."""


def single_job(job: Job) -> Analysis:
    """The analysis that is ``job`` alone: its value is the job's result."""
    return (yield job)


def _inline(job: Job) -> Future:
    """``job`` run now, as a finished future (its result or its exception)."""
    future: Future = Future()
    try:
        future.set_result(job.fn(*job.args, **job.kwargs))
    except Exception as exc:  # noqa: BLE001 - handed to the analysis, as a call would raise
        future.set_exception(exc)
    return future


class JobRunner:
    """Where jobs run: inline, or on ``worker`` until it breaks (then inline).

    Args:
        worker: the executor of the jobs; None: inline.
    """

    def __init__(self, worker: Executor | None = None) -> None:
        """Inline unless a worker is given."""
        self._worker = worker
        self.lost = ""
        """Why the worker was given up ('' while it serves, or with none)."""
        self._told = False

    @property
    def inline(self) -> bool:
        """True when jobs run on the calling thread."""
        return self._worker is None

    def lost_news(self) -> str:
        """Why the worker was given up, the first time it is asked after; else ''."""
        if not self.lost or self._told:
            return ""
        self._told = True
        return self.lost

    def submit(self, job: Job) -> Future:
        """``job`` started on the worker, or run inline (finished) without one."""
        if self._worker is None:
            return _inline(job)
        try:
            return self._worker.submit(job.fn, *job.args, **job.kwargs)
        except (BrokenExecutor, RuntimeError) as exc:     # broken, or shut down
            return self._give_up(job, exc)

    def outcome(self, job: Job, future: Future) -> tuple[Any, BaseException | None]:
        """(result, exception) of a finished ``future``; a broken worker's job rerun inline."""
        exc = future.exception()
        if isinstance(exc, BrokenExecutor):
            future = self._give_up(job, exc)
            exc = future.exception()
        return (None if exc is not None else future.result()), exc

    def _give_up(self, job: Job, exc: BaseException) -> Future:
        """The worker is unusable: say why, run ``job`` and every later one inline."""
        self.lost = (f"the analysis worker is lost ({type(exc).__name__}: {exc}); "
                     "analysing on the loop thread")
        self._worker = None
        return _inline(job)


class Pieces:
    """Runs an :data:`Analysis` one piece per :meth:`step`, its jobs on ``runner``.

    A piece ends at a bare ``yield``, or at a job that is not finished yet (then the next
    steps wait for it). Inline, a job's piece goes on at once.
    """

    def __init__(self, analysis: Analysis, runner: JobRunner) -> None:
        """Not started: the first step runs the first piece."""
        self._analysis = analysis
        self._runner = runner
        self._pending: tuple[Job, Future] | None = None
        self.value: Any = None
        """The analysis's return value, once it ended."""

    @property
    def waiting(self) -> bool:
        """True while a job of the analysis runs on the worker."""
        return self._pending is not None

    def step(self) -> bool:
        """The next piece (or a wait for a job's result). True once the analysis ended.

        An exception of the analysis (or of a job it does not catch) propagates.
        """
        value: Any = None
        exc: BaseException | None = None
        if self._pending is not None:
            job, future = self._pending
            if not future.done():
                return False
            self._pending = None
            value, exc = self._runner.outcome(job, future)
        try:
            while True:
                job = (self._analysis.throw(exc) if exc is not None
                       else self._analysis.send(value))
                if job is None:
                    return False
                future = self._runner.submit(job)
                if not future.done():
                    self._pending = (job, future)
                    return False
                value, exc = self._runner.outcome(job, future)
        except StopIteration as stop:
            self.value = stop.value
            return True

    def close(self) -> None:
        """Stop the analysis; a job of it still waiting is cancelled (its result dropped)."""
        if self._pending is not None:
            self._pending[1].cancel()
            self._pending = None
        self._analysis.close()


def run_inline(analysis: Analysis) -> Any:
    """Run ``analysis`` to its end on this thread, every piece and job at once; its value."""
    return run_waiting(analysis, JobRunner(), _nothing)


def run_waiting(analysis: Analysis, runner: JobRunner, idle: Callable[[], None]) -> Any:
    """Run ``analysis`` to its end now, its jobs on ``runner``; its value.

    While a job runs on the worker, ``idle()`` is called again and again (e.g. the node
    serving its 1 kHz loop for a moment): the caller waits for the result without stalling
    what ``idle`` serves. Inline every job is done at once and ``idle`` is never called.
    """
    pieces = Pieces(analysis, runner)
    while not pieces.step():
        if pieces.waiting:
            idle()
    return pieces.value


def _nothing() -> None:
    """No wait: inline, nothing is ever waited for."""


class WaitingJobs:
    """Computations that must finish before their caller goes on (:func:`run_waiting`).

    Inline unless :meth:`serve_with` gave the function that serves the caller's loop while
    a job runs on ``runner``'s worker. Inline too: a computation started while another one
    waits (the loop served meanwhile may need one: no nesting), and any inside
    :meth:`inline` (a caller that is changing state the loop reads).
    """

    def __init__(self, runner: JobRunner | None = None) -> None:
        """Jobs on ``runner`` (None: inline) once a loop to serve is given."""
        self._runner = runner or JobRunner()
        self._idle: Callable[[], None] | None = None
        self._blocked = 0

    def serve_with(self, idle: Callable[[], None] | None) -> None:
        """Call ``idle`` while a job runs on the worker (None: run every job inline)."""
        self._idle = idle

    @property
    def serving(self) -> bool:
        """True when a computation could run on the worker while the loop is served."""
        return self._idle is not None and not self._blocked and not self._runner.inline

    def run(self, analysis: Analysis) -> Any:
        """Run ``analysis`` to its end; its value (see the class)."""
        idle = self._idle
        if idle is None or self._blocked or self._runner.inline:
            return run_inline(analysis)
        with self.inline():
            return run_waiting(analysis, self._runner, idle)

    @contextmanager
    def inline(self) -> Iterator[None]:
        """Every computation inside runs inline (the loop is not served meanwhile)."""
        self._blocked += 1
        try:
            yield
        finally:
            self._blocked -= 1
