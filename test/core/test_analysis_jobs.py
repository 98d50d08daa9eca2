"""An identification's analysis in pieces, its heavy jobs inline or on a worker.

Inline, a job's piece goes on in the same step (the lockstep schedule); on a worker the
analysis waits for the result, step after step. Real executors: a thread pool where a test
holds a job back with an event, a spawned process pool for the supervisor (every argument
crosses a pickle), one whose process dies for the fallback.
"""

import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
from static_rig import coupled_gain, run

from hexapod_vibration.contract import NotchState
from hexapod_vibration.core.control.notch_supervisor import NotchConfig, NotchSupervisor
from hexapod_vibration.core.control.supervisor.analysis_jobs import (
    Job,
    JobRunner,
    Pieces,
    WaitingJobs,
    run_inline,
    single_job,
)
from hexapod_vibration.core.sim.scenario import notch_preset

HANG_GUARD_S = 120.0
"""A worker's job takes ~1 s; this only ends a test whose worker never answers."""


def _finish(pieces: Pieces) -> None:
    """Step ``pieces`` until the analysis ends (a hang guard, not a timing check)."""
    deadline = time.monotonic() + HANG_GUARD_S
    while not pieces.step():
        assert time.monotonic() < deadline, "the worker never answered"
        time.sleep(0.001)


def _square(x: float) -> float:
    return x * x


def _fail(message: str) -> float:
    raise ValueError(message)


def _exit_unless_in(pid: int) -> str:
    """Kills a worker process (its pool breaks); in the process ``pid`` it returns."""
    if os.getpid() != pid:
        os._exit(3)
    return "inline"


def _analysis(log: list):
    """Two pieces: a job and a bare yield, then a job whose error is caught."""
    log.append((yield Job(_square, (3.0,))))
    yield
    try:
        yield Job(_fail, ("no",))
    except ValueError as exc:
        log.append(str(exc))
    return "done"


def test_inline_a_job_goes_on_in_the_same_piece():
    log: list = []
    pieces = Pieces(_analysis(log), JobRunner())
    assert pieces.step() is False and log == [9.0]         # the job's piece went on
    assert pieces.step() is True and log == [9.0, "no"]     # the error reached the analysis
    assert pieces.value == "done" and not pieces.waiting
    assert run_inline(_analysis([])) == "done"


def test_on_a_worker_the_analysis_waits_for_the_result_step_after_step():
    release = threading.Event()

    def held(x: float) -> float:
        release.wait()
        return x + 1.0

    def analysis(log: list):
        log.append((yield Job(held, (1.0,))))
        return "done"

    log: list = []
    with ThreadPoolExecutor(1) as worker:
        pieces = Pieces(analysis(log), JobRunner(worker))
        for _ in range(5):
            assert pieces.step() is False and pieces.waiting
        assert log == []
        release.set()
        _finish(pieces)
    assert log == [2.0] and pieces.value == "done"


def test_closing_drops_a_job_still_waiting():
    release = threading.Event()
    closed: list = []

    def analysis():
        try:
            yield Job(release.wait)
            closed.append("resumed")
        finally:
            closed.append("closed")

    with ThreadPoolExecutor(1) as worker:
        pieces = Pieces(analysis(), JobRunner(worker))
        pieces.step()
        pieces.close()
        release.set()
    assert closed == ["closed"]


def test_a_worker_that_dies_is_given_up_and_the_job_runs_inline():
    def analysis():
        first = yield Job(_exit_unless_in, (os.getpid(),))
        second = yield Job(_square, (2.0,))
        return first, second

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as worker:
        runner = JobRunner(worker)
        pieces = Pieces(analysis(), runner)
        _finish(pieces)
    assert pieces.value == ("inline", 4.0)
    assert runner.inline and "analysis worker is lost" in runner.lost_news()
    assert runner.lost_news() == ""                        # said once


def _broadband() -> NotchConfig:
    base = {**notch_preset("paper"), "tone_frequencies_hz": (40.0,), "enabled": True,
            "identify_delay_s": 0.1, "identification": "broadband", "mu_policy": "auto"}
    return NotchConfig().replaced(base)


def _analysing(sup: NotchSupervisor) -> bool:
    return sup.identification.analysis is not None


def _engaged(sup: NotchSupervisor, k: np.ndarray, start: int, wait_s: float) -> int:
    """Samples until the analysis ends (a worker's: the loop sleeps while it waits)."""
    n, deadline = start, time.monotonic() + HANG_GUARD_S
    while _analysing(sup):
        assert time.monotonic() < deadline, "the worker never answered"
        run(sup, k, 1, n)
        n += 1
        if sup.identification.analysis is not None and sup.identification.analysis.waiting:
            time.sleep(wait_s)
    return n


def test_an_analysis_on_a_worker_process_puts_in_force_what_the_inline_one_does():
    """Same G(f), bound, policy rates, P and prediction; control on a few samples later."""
    k = coupled_gain(0.1)
    inline = NotchSupervisor(_broadband())
    start = len(run(inline, k, 20_000, until=_analysing))
    inline_end = _engaged(inline, k, start, 0.0)
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as worker:
        sup = NotchSupervisor(_broadband(), analysis_worker=worker)
        assert len(run(sup, k, 20_000, until=_analysing)) == start
        end = _engaged(sup, k, start, 0.0005)
    assert inline.state == sup.state == NotchState.ADAPTING
    assert end > inline_end > start
    assert sup.bound == inline.bound and sup.canceller.mu == inline.canceller.mu
    assert np.array_equal(sup.canceller.coefficients, inline.canceller.coefficients)
    mine, theirs = sup.status(), inline.status()
    for key in ("tone_mu", "predicted_rise_db", "mu_limit", "plant_gain_m_s2_per_n"):
        assert mine[key] == theirs[key], key
    assert mine["identification_end_sample"] > theirs["identification_end_sample"]
    assert not [e for e in sup.drain_events() if "lost" in e.message]


def test_a_worker_shut_down_is_given_up_and_the_job_runs_inline():
    worker = ThreadPoolExecutor(1)
    worker.shutdown()
    runner = JobRunner(worker)
    assert runner.submit(Job(_square, (5.0,))).result() == 25.0
    assert runner.inline and "RuntimeError" in runner.lost


def test_new_tones_while_a_job_runs_on_the_worker_take_over():
    """The analysis waiting for the worker stops for new tones; they are engaged after it."""
    k = coupled_gain(0.1)
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as worker:
        sup = NotchSupervisor(_broadband(), analysis_worker=worker)
        start = len(run(sup, k, 20_000, until=_analysing))
        n = start + len(run(sup, k, 100, start,
                            until=lambda s: s.identification.analysis.waiting))
        assert sup.identification.analysis.waiting         # G(f) from the record, on it
        sup.apply({"tone_frequencies_hz": [40.0, 80.0]})
        assert sup.state == NotchState.IDENTIFYING
        _engaged(sup, k, n, 0.0005)
    assert sup.state == NotchState.ADAPTING
    assert sup.canceller.coefficients.shape == (2, 6, 6)
    assert sup.plant_response.shape == (2, 6, 6)


def test_a_lost_worker_is_said_once_and_the_loop_thread_analyses():
    k = coupled_gain(0.1)
    worker = ThreadPoolExecutor(1)
    worker.shutdown()
    sup = NotchSupervisor(_broadband(), analysis_worker=worker)
    start = len(run(sup, k, 20_000, until=_analysing))
    _engaged(sup, k, start, 0.0)
    assert sup.state == NotchState.ADAPTING
    lost = [e for e in sup.drain_events() if "analysis worker is lost" in e.message]
    assert [e.level for e in lost] == ["warn"]


def test_waiting_jobs_serve_the_loop_only_while_a_job_runs_on_the_worker():
    """Inline: no idle. On a worker: idle until the result; nested or in inline(): none."""
    assert WaitingJobs().run(single_job(Job(_square, (3.0,)))) == 9.0
    release = threading.Event()
    idles: list[str] = []
    with ThreadPoolExecutor(1) as worker:
        waits = WaitingJobs(JobRunner(worker))
        assert waits.run(single_job(Job(_square, (2.0,)))) == 4.0    # no loop to serve: inline

        def idle() -> None:
            # The loop served meanwhile may need a computation itself: inline, no nesting.
            idles.append(f"nested {waits.run(single_job(Job(_square, (len(idles),))))}")
            if len(idles) == 3:
                release.set()

        waits.serve_with(idle)
        assert waits.run(single_job(Job(lambda: release.wait() and "held"))) == "held"
        assert idles[:3] == ["nested 0", "nested 1", "nested 4"]
        idles.clear()
        with waits.inline():
            assert waits.run(single_job(Job(_square, (5.0,)))) == 25.0
        assert idles == []


def _adapting_pair(worker, k: np.ndarray, change: dict) -> tuple[NotchSupervisor, ...]:
    """An inline supervisor with ``change`` applied, a worker's one adapting, at the same sample."""
    config = NotchConfig().replaced({"tone_frequencies_hz": [40.0], "identify_delay_s": 0.1})
    inline = NotchSupervisor(config)
    n = _engaged(inline, k, len(run(inline, k, 30_000, until=_analysing)), 0.0)
    run(inline, k, 1000, n)
    inline.check(change)
    inline.apply(change)
    sup = NotchSupervisor(config, analysis_worker=worker)
    n = _engaged(sup, k, len(run(sup, k, 30_000, until=_analysing)), 0.0005)
    run(sup, k, 1000, n)
    assert sup.state == NotchState.ADAPTING
    return inline, sup, n + 1000


def _chosen(sup: NotchSupervisor, k: np.ndarray, n: int) -> int:
    """Samples until the mu policy's choice is in force (the loop sleeps while it waits)."""
    deadline = time.monotonic() + HANG_GUARD_S
    while sup.mu_choice is None or sup._choice.running:
        assert time.monotonic() < deadline, "the worker never answered"
        run(sup, k, 1, n)
        n += 1
        time.sleep(0.0005)
    return n


def test_a_tone_change_with_a_worker_serves_the_loop_and_decides_as_inline():
    """The check's limit on a worker while the loop runs; the apply waits for nothing.

    The mu policy's choice is made on the worker while the loop adapts with the normalised P.

    The node's idle, here: one sample of the static rig per call (it does not wait for the
    worker's answer, so the count of samples it served depends on the machine).
    """
    k = coupled_gain(0.2)
    change = {"tone_frequencies_hz": [40.0, 80.0]}
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as worker:
        inline, sup, n = _adapting_pair(worker, k, change)
        served = [n]

        def idle() -> None:
            run(sup, k, 1, served[-1])
            served.append(served[-1] + 1)
            time.sleep(0.0005)

        sup.serve_while_waiting(idle)
        sup.check(change)                          # the Nyquist limit, on the worker
        in_check = len(served) - 1
        sup.apply(change)                          # the same limit, kept; nothing waited for
        assert len(served) - 1 == in_check > 0 and sup.last_sample == served[-1] - 1
        assert sup.mu_choice is None and sup._choice.running
        assert sup.canceller.adapting.all() and sup.canceller.mu > 0.0
        assert sup.status()["tone_mu"] == []
        after = _chosen(sup, k, served[-1])
        assert after > served[-1]
    assert sup.bound == inline.bound > 0.0
    assert sup.state == inline.state == NotchState.ADAPTING
    assert np.array_equal(sup.canceller.coefficients, inline.canceller.coefficients)
    assert sup.status()["tone_mu"] == inline.status()["tone_mu"] != []
    assert sup._rates.type2_max_mu == inline._rates.type2_max_mu


def test_a_second_change_while_the_choice_is_made_drops_it_and_chooses_again():
    """A change drops a choice in progress (held on the worker) and starts it again."""
    k = coupled_gain(0.2)
    first, second = {"tone_frequencies_hz": [40.0, 80.0]}, {"tone_frequencies_hz": [40.0, 90.0]}
    release = threading.Event()
    with ThreadPoolExecutor(1) as worker:
        try:
            inline, sup, n = _adapting_pair(worker, k, second)
            sup.serve_while_waiting(lambda: time.sleep(0.0005))
            sup.apply(first)
            worker.submit(release.wait)            # the choice's job queues behind this one
            kept = sup.canceller.weights[0].copy()
            run(sup, k, 5, n)
            assert sup._choice.running and sup.mu_choice is None
            assert not sup.canceller.coefficients.any()            # adaptation held
            assert np.array_equal(sup.canceller.weights[0], kept) and kept.any()
            sup.apply({"enabled": True})           # dropped, and started again for its P
            assert sup._choice.running and sup._rates.unchosen is not None
        finally:
            release.set()                          # (the next change's limit runs there)
        sup.apply(second)                          # dropped, and made for the new tones
        _chosen(sup, k, n + 5)
    assert sup.canceller.tone_frequencies_hz.tolist() == [40.0, 90.0]
    assert np.array_equal(sup.mu_choice.tone_mu, inline.mu_choice.tone_mu)
    assert np.array_equal(sup.canceller.coefficients, inline.canceller.coefficients)
    assert sup._rates.unchosen is None
