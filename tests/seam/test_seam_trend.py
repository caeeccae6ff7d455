"""Trend filtering (eq. 10): knots at the true corners of a piecewise-linear path, error <= eps."""

import itertools

import numpy as np
import pytest

from posekit.errors import EstimationError
from posekit.seam.engine.trend import trend_filter

CORNERS = [0, 30, 45, 60, 99]


def _piecewise_linear():
    t = np.arange(100.0)
    return np.c_[t, np.interp(t, [0, 30, 60, 99], [0, 15, -5, 10]), np.interp(t, [0, 45, 99], [0, 5, 0])]


@pytest.mark.parametrize("eps", [0.01, 0.1])
def test_knots_at_true_corners_and_error_within_eps(eps):
    y = _piecewise_linear()
    res = trend_filter(y, lam=100.0, eps_mm=eps)
    assert res.status == "optimal"
    assert res.knots.tolist() == CORNERS
    assert res.max_error_mm <= eps * (1 + 1e-6)
    np.testing.assert_allclose(res.polyline, res.z[CORNERS])
    # the approximation is affine between the knots
    for a, b in itertools.pairwise(CORNERS):
        t = (np.arange(a, b + 1) - a) / (b - a)
        line = res.z[a] + t[:, None] * (res.z[b] - res.z[a])
        np.testing.assert_allclose(res.z[a:b + 1], line, atol=1e-5)


def test_noisy_path_stays_within_eps_with_few_knots():
    rng = np.random.default_rng(0)
    y = _piecewise_linear() + rng.uniform(-0.02, 0.02, size=(100, 3))
    res = trend_filter(y, lam=100.0, eps_mm=0.05)
    assert res.max_error_mm <= 0.05 * (1 + 1e-6)
    assert len(res.knots) <= 12
    # every true interior corner has a knot within one sample
    for c in CORNERS[1:-1]:
        assert np.min(np.abs(res.knots - c)) <= 1


def test_straight_line_has_only_its_ends():
    t = np.linspace(0.0, 200.0, 401)
    res = trend_filter(np.c_[0.3 * t, t, -0.1 * t + 4.0], lam=10.0, eps_mm=0.02)
    assert res.knots.tolist() == [0, 400]
    assert res.max_error_mm < 1e-6


@pytest.mark.parametrize(
    "y, kw, message",
    [
        (np.zeros((2, 3)), {}, r"expected y of shape \(N >= 3, 3\), got \(2, 3\)"),
        (np.zeros((5, 2)), {}, r"expected y of shape \(N >= 3, 3\), got \(5, 2\)"),
        (np.full((5, 3), np.nan), {}, "y has non-finite values"),
        (np.zeros((5, 3)), {"eps_mm": 0.0}, "expected eps_mm > 0, got 0.0"),
        (np.zeros((5, 3)), {"lam": -1.0}, "expected lam >= 0, got -1.0"),
    ],
)
def test_bad_input(y, kw, message):
    with pytest.raises(EstimationError, match=message):
        trend_filter(y, **kw)


def test_a_solver_that_stops_early_is_an_error_not_a_result(monkeypatch):
    """The status is checked: Clarabel cut to one iteration ('user_limit') raises, it does not return knots."""
    import clarabel

    default_settings = clarabel.DefaultSettings

    def one_iteration():
        settings = default_settings()
        settings.max_iter = 1
        return settings

    monkeypatch.setattr(clarabel, "DefaultSettings", one_iteration)
    with pytest.raises(EstimationError, match=r"^trend filter: solver status 'user_limit', expected 'optimal' "
                                              r"\(N = 100, lam = 100, eps = 0\.02 mm\)$"):
        trend_filter(_piecewise_linear(), lam=100.0, eps_mm=0.02)


def test_an_infeasible_problem_is_an_error(monkeypatch):
    """Any status but Clarabel's Solved is an error, named with cvxpy's word for it."""
    import clarabel

    solver = clarabel.DefaultSolver

    def negative_eps(P, q, A, b, cones, settings):
        b = b.copy()
        b[-2 * 3 * 100:] = -1.0         # the last 2 x 3N rows are -eps <= z - y <= eps: now eps = -1
        return solver(P, q, A, b, cones, settings)

    monkeypatch.setattr(clarabel, "DefaultSolver", negative_eps)
    with pytest.raises(EstimationError, match=r"^trend filter: solver status 'infeasible', expected 'optimal' "):
        trend_filter(_piecewise_linear(), lam=100.0, eps_mm=0.02)
