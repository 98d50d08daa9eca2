"""SampleSet: the loop samples seen on a topic."""

from __future__ import annotations

from hexapod_vibration.core.loop.sample_set import SAMPLE_LOOKAHEAD, SampleSet


def test_a_sample_is_new_once_then_seen():
    seen = SampleSet()
    assert seen.add(0) is False
    assert seen.add(0) is True
    assert seen.add(40_000) is False                      # grows past its buffer
    assert seen.add(39_999) is False
    assert seen.add(40_000) is True


def test_an_index_far_beyond_the_loop_is_not_marked():
    seen = SampleSet()
    seen.add(5)
    far = 2 * SAMPLE_LOOKAHEAD
    assert seen.add(far) is None
    assert seen.add(far) is None                          # still not a loop sample
