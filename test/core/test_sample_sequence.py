"""Run identity and index plausibility (core/loop/sample_sequence.py), without ROS.

The cases: a restarted driver (new run from sample 0) is followed, one bogus
index or stray run changes nothing, repeats and late samples are told apart.
"""

import pytest

from hexapod_vibration.core.loop.sample_sequence import (
    CONFIRMATIONS,
    MAX_JUMP_SAMPLES,
    Admission,
    SampleSequence,
)

A, B = 111, 222


def _feed(sequence, messages):
    return [sequence.admit(index, run) for index, run in messages]


def test_first_message_is_adopted_then_the_next_ones_accepted():
    seq = SampleSequence()
    first, *rest = _feed(seq, [(5000, A), (5001, A), (5003, A)])
    assert first.admission is Admission.NEW_RUN and first.index == 5000
    assert [v.admission for v in rest] == [Admission.ACCEPTED] * 2
    assert [v.gap for v in rest] == [0, 1]
    assert (seq.run, seq.last, seq.runs_adopted) == (A, 5003, 1)


def test_repeat_and_late_are_not_acted_on():
    seq = SampleSequence()
    _feed(seq, [(10, A), (11, A)])
    repeat, late = _feed(seq, [(11, A), (3, A)])
    assert repeat.admission is Admission.REPEAT and not repeat.act
    assert late.admission is Admission.LATE and not late.act
    assert seq.last == 11


def test_missing_index_is_the_next_sample():
    seq = SampleSequence()
    verdicts = _feed(seq, [(None, None), (None, None), (7, None)])
    assert [v.index for v in verdicts] == [0, 1, 7]
    assert verdicts[2].gap == 5


def test_restarted_driver_in_lockstep_is_followed_within_the_confirmations():
    """The new driver offers sample 0 again and again (handshake): adopted at the 3rd."""
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(49990, 50000)])
    verdicts = _feed(seq, [(0, B)] * CONFIRMATIONS)
    assert [v.admission for v in verdicts] == [Admission.UNCONFIRMED] * (CONFIRMATIONS - 1) + [
        Admission.NEW_RUN]
    assert (seq.run, seq.last) == (B, 0)
    assert seq.admit(1, B).admission is Admission.ACCEPTED


def test_restarted_driver_in_realtime_is_followed_within_the_confirmations():
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(100, 200)])
    verdicts = _feed(seq, [(n, B) for n in range(10)])
    acted = [v.index for v in verdicts if v.act]
    assert acted == list(range(CONFIRMATIONS - 1, 10))
    assert verdicts[CONFIRMATIONS - 1].admission is Admission.NEW_RUN


def test_one_bogus_index_changes_nothing():
    """Old controllers: sample 99999999999 ahead stopped the notch for good."""
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(100)])
    bogus = seq.admit(99_999_999_999, A)
    assert bogus.admission is Admission.UNCONFIRMED
    verdicts = _feed(seq, [(n, A) for n in range(100, 200)])
    assert all(v.admission is Admission.ACCEPTED and v.gap == 0 for v in verdicts)
    assert seq.last == 199


def test_bogus_messages_interleaved_with_the_run_are_never_adopted():
    seq = SampleSequence()
    seq.admit(0, A)
    for n in range(1, 300):
        assert seq.admit(n, A).act
        assert not seq.admit(10**9 + n, A).act           # absurd, but increasing
        assert not seq.admit(n, B).act                   # a stray run
    assert (seq.run, seq.last, seq.runs_adopted) == (A, 299, 1)


def test_a_confirmed_jump_within_the_run_is_a_gap():
    """A controller that was stopped for minutes resumes with the driver's current index."""
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(10)])
    far = 9 + 3 * MAX_JUMP_SAMPLES
    verdicts = _feed(seq, [(far + k, A) for k in range(CONFIRMATIONS)])
    assert [v.act for v in verdicts] == [False] * (CONFIRMATIONS - 1) + [True]
    assert verdicts[-1].admission is Admission.ACCEPTED
    assert verdicts[-1].gap == far + CONFIRMATIONS - 1 - 10
    assert seq.runs_adopted == 1


def test_a_candidate_must_be_consecutive():
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(10)])
    assert not seq.admit(0, B).act
    assert seq.admit(10, A).act                          # the current run goes on
    assert not seq.admit(1, B).act                       # the count starts again
    assert not seq.admit(2, B).act
    assert seq.admit(3, B).admission is Admission.NEW_RUN


def test_a_candidate_going_backwards_starts_again():
    seq = SampleSequence(confirmations=2)
    seq.admit(50, A)
    assert not seq.admit(10, B).act
    assert not seq.admit(5, B).act                       # not a continuation
    assert seq.admit(6, B).admission is Admission.NEW_RUN


def test_parameters_are_checked():
    with pytest.raises(ValueError):
        SampleSequence(max_jump_samples=0)
    with pytest.raises(ValueError):
        SampleSequence(confirmations=0)


def test_a_bogus_sequence_that_took_over_is_taken_back_by_the_real_stream():
    """Three consistent bogus messages (a paused loop) take over; the real stream takes back.

    They look like a restart, by design; the real stream wins within three messages.
    """
    seq = SampleSequence()
    _feed(seq, [(n, A) for n in range(100)])
    bogus = _feed(seq, [(10**9, A)] * CONFIRMATIONS)
    assert bogus[-1].act and seq.last == 10**9
    real = _feed(seq, [(n, A) for n in range(100, 110)])
    assert [v.admission for v in real[:CONFIRMATIONS - 1]] == [Admission.LATE] * 2
    assert real[CONFIRMATIONS - 1].admission is Admission.NEW_RUN       # re-synchronised
    assert all(v.admission is Admission.ACCEPTED for v in real[CONFIRMATIONS:])
    assert seq.last == 109


def test_a_publisher_without_runs_that_starts_again_is_followed():
    seq = SampleSequence()
    _feed(seq, [(n, None) for n in range(5000)])
    verdicts = _feed(seq, [(n, None) for n in range(5)])
    assert [v.act for v in verdicts] == [False, False, True, True, True]
    assert verdicts[2].admission is Admission.NEW_RUN and seq.last == 4
