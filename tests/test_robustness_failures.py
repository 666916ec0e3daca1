"""The failure split of benchmarks/robustness_failures.py: strikes against other failures."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.robustness_failures import point_failures


def test_failures_split_into_strikes_and_the_rest():
    """Of four failures, the two with a wrist peak at or above the limit are strikes; the other
    two keep their peaks; the successes' median peak ignores the failures."""
    success = np.array([True, True, False, False, False, False])
    peak = np.array([10.0, 30.0, 100.0, 140.0, 99.9, 12.0])
    split = point_failures(success, peak, strike=100.0)
    assert split["episodes"] == 6
    assert split["success_rate"] == pytest.approx(2 / 6)
    assert (split["failures"], split["strikes"]) == (4, 2)
    assert split["median_peak_success"] == pytest.approx(20.0)
    assert split["peaks_of_other_failures"] == [12.0, 99.9]


def test_a_point_with_no_success_has_no_success_peak():
    split = point_failures(np.zeros(3, bool), np.array([5.0, 120.0, 7.0]), strike=100.0)
    assert split["median_peak_success"] is None
    assert (split["failures"], split["strikes"]) == (3, 1)
