"""posekit._student_t: Student's t tail and upper quantile in plain Python, against scipy.stats.t."""

import math

import numpy as np
import pytest
from scipy.stats import t

from posekit._student_t import t_isf, t_sf


@pytest.mark.parametrize("dof", [0.7, 1.0, 2.0, 3.3, 9.9, 30.0, 300.0, 1e5])
def test_tail_and_quantile_match_scipy(dof):
    for x in (-40.0, -2.0, 0.0, 0.3, 1.0, 5.0, 40.0):
        assert t_sf(x, dof) == pytest.approx(float(t.sf(x, dof)), rel=1e-9, abs=1e-15)
    for alpha in (0.9, 0.4, 0.05, 1e-3 / 12, 1e-7):
        assert t_isf(alpha, dof) == pytest.approx(float(t.isf(alpha, dof)), rel=1e-9)


def test_quantile_round_trips_through_the_tail():
    for dof in (1.5, 4.0, 17.0):
        for alpha in (0.2, 1e-2, 1e-5):
            assert t_sf(t_isf(alpha, dof), dof) == pytest.approx(alpha, rel=1e-9)


def test_bad_arguments_are_nan_and_the_ends_are_infinite():
    assert math.isnan(t_isf(0.0, 3.0)) and math.isnan(t_isf(1.0, 3.0)) and math.isnan(t_isf(0.1, 0.0))
    assert math.isnan(t_isf(0.1, np.inf)) and math.isnan(t_sf(np.nan, 3.0)) and math.isnan(t_sf(1.0, -1.0))
    assert t_isf(0.5, 3.0) == 0.0
    assert t_sf(np.inf, 3.0) == 0.0 and t_sf(-np.inf, 3.0) == 1.0
