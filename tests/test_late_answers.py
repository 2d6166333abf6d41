"""When late answers become a fault (:mod:`leadthrough.drivers.late_answers`): isolated ones
are counted, runs are a fault, well below RSI's own limit of 100 in a row."""

from __future__ import annotations

import pytest

from leadthrough.drivers.late_answers import (
    LATE_IN_WINDOW,
    LATE_RUN,
    LATE_WINDOW,
    LateAnswerTolerance,
)

RSI_TIMEOUT = 100   # the shipped context's Timeout: late answers in a row before RSI stops


def test_the_limits_are_well_below_rsis_own() -> None:
    assert 1 < LATE_RUN <= RSI_TIMEOUT // 10
    assert LATE_RUN <= LATE_IN_WINDOW <= LATE_WINDOW // 10   # at most 10 % of the cycles late


def test_isolated_late_answers_are_counted_not_a_fault() -> None:
    tol = LateAnswerTolerance()
    spacing = LATE_WINDOW // (LATE_IN_WINDOW - 1) + 1   # never LATE_IN_WINDOW in a window
    faults = [tol.update(k, int(k % spacing == 0)) for k in range(20 * LATE_WINDOW)]
    assert not any(faults)
    assert tol.late == len(range(0, 20 * LATE_WINDOW, spacing)) and tol.longest_run == 1


def test_a_run_is_a_fault_at_its_last_answer() -> None:
    tol = LateAnswerTolerance()
    assert not any(tol.update(k, 1) for k in range(100, 100 + LATE_RUN - 1))
    assert tol.update(100 + LATE_RUN - 1, 1)
    assert tol.run_now == LATE_RUN
    assert not tol.update(100 + LATE_RUN, 0) and tol.run_now == 0   # an answer on time ends it


def test_a_gap_in_the_sequence_breaks_a_run() -> None:
    tol = LateAnswerTolerance()
    for k in (10, 11, 12, 13, 15, 16, 17, 18):     # 4 in a row, a document unseen, 4 again
        assert not tol.update(k, 1)
    assert tol.longest_run == LATE_RUN - 1


def test_one_document_reporting_a_run_is_a_fault() -> None:
    """A document whose count grew by k: the k cycles before it went unanswered in time."""
    tol = LateAnswerTolerance()
    assert not tol.update(50, LATE_RUN - 1)
    tol.reset()
    assert tol.update(50, LATE_RUN) and tol.late == LATE_RUN


def test_crowded_late_answers_are_a_fault() -> None:
    tol = LateAnswerTolerance()
    spacing = (LATE_WINDOW - 1) // LATE_IN_WINDOW       # LATE_IN_WINDOW within the window
    got = [tol.update(k * spacing, 1) for k in range(LATE_IN_WINDOW)]
    assert got == [False] * (LATE_IN_WINDOW - 1) + [True]


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="in_window"):
        LateAnswerTolerance(run=5, in_window=3, window=250)
