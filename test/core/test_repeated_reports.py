"""The driver's reports repeat the rows of the reports before them; a reader takes each once."""

from hexapod_vibration.core.loop.repeated_reports import FreshRows, RepeatedRows


def _reports(count: int, repeat: int) -> list[tuple[list, int]]:
    """``count`` reports of one row each (samples 100 k .. 100 k + 9), as sent."""
    sent = RepeatedRows(repeat)
    return [(sent.rows([(100 * k, 100 * k + 9, -1, 0.0)]), 100 * k + 99) for k in range(count)]


def test_each_report_repeats_the_rows_of_the_reports_before_it():
    reports = _reports(5, repeat=3)
    assert [len(rows) for rows, _ in reports] == [1, 2, 3, 3, 3]
    assert reports[4][0] == [(200, 209, -1, 0.0), (300, 309, -1, 0.0), (400, 409, -1, 0.0)]


def test_a_reader_takes_every_row_once_despite_lost_and_repeated_reports():
    reports = _reports(8, repeat=3)
    fresh, taken = FreshRows(), []
    for k in (0, 1, 1, 3, 5, 4, 6, 7):          # 2 lost, 1 twice, 4 after 5 (late)
        rows = fresh.take(*reports[k], run=9)
        taken += rows or []
    assert taken == [(100 * k, 100 * k + 9, -1, 0.0) for k in range(8)]


def test_a_report_of_a_new_run_starts_afresh_and_rows_lost_beyond_the_repeat_are_gone():
    fresh = FreshRows()
    assert fresh.take([(0, 9)], 99, run=1) == [(0, 9)]
    assert fresh.take([(0, 9)], 99, run=2) == [(0, 9)]            # a restarted driver
    reports = _reports(6, repeat=2)
    fresh = FreshRows()
    fresh.take(*reports[0], run=1)
    assert fresh.take(*reports[5], run=1) == [(400, 409, -1, 0.0), (500, 509, -1, 0.0)]
