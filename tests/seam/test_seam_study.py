"""Tuning study (posekit.seam.study): OLS effects against a hand-rolled t-test, ranking, factors,
and a tiny end-to-end study that gives the same table in one process and on a 2-worker cluster."""

import csv

import numpy as np
import pytest
from scipy import stats

from posekit.errors import ConfigError, EstimationError
from posekit.seam.study import (
    ERROR_NAMES,
    RANKED_COLUMNS,
    Factor,
    fit_parameter_effects,
    get_dotted,
    make_factors,
    rank_parameters,
    set_dotted,
)

PARAMS = ("strong", "weak", "none_a", "none_b")


def _synthetic(seed=0, n=60):
    """x0 drives every error strongly, x1 only rz weakly, x2/x3 nothing."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([0, 0, 0, 0], [1, 2, 3, 4], size=(n, 4))
    Y = 0.1 * rng.standard_normal((n, 6))
    Y += 2.0 * X[:, [0]]
    Y[:, 5] += 0.05 * X[:, 1]
    return X, Y


def _ols_reference(X, y):
    """Textbook OLS: slopes and two-sided t-test p-values (numpy + scipy only)."""
    A = np.c_[np.ones(len(X)), X]
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ beta
    dof = len(X) - A.shape[1]
    s2 = resid @ resid / dof
    se = np.sqrt(np.diag(s2 * np.linalg.inv(A.T @ A)))
    t = beta / se
    return beta[1:], 2 * stats.t.sf(np.abs(t), dof)[1:]


def test_effects_match_textbook_ols():
    X, Y = _synthetic()
    eff = fit_parameter_effects(X, Y, PARAMS)
    assert eff.n == 60 and eff.coef.shape == (6, 4)
    for e in range(6):
        beta, p = _ols_reference(X, Y[:, e])
        np.testing.assert_allclose(eff.coef[e], beta, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(eff.pvalues[e], p, rtol=1e-6, atol=1e-300)
    np.testing.assert_allclose(eff.coef[:, 0], 2.0, atol=0.1)
    assert np.all(eff.log10_p[:, 0] < -30)
    assert np.all(eff.rsquared > 0.95)


def test_rank_puts_strong_factor_first():
    X, Y = _synthetic()
    factors = [Factor(n, 0.0, hi) for n, hi in zip(PARAMS, (1, 2, 3, 4))]
    rows = rank_parameters(fit_parameter_effects(X, Y, PARAMS), factors)
    assert [r["rank"] for r in rows] == [1, 2, 3, 4]
    assert rows[0]["parameter"] == "strong" and rows[0]["significant"] == "yes"
    assert rows[0]["range_effect_x_mm"] == pytest.approx(2.0, abs=0.1)       # slope 2 over a range of 1
    assert {r["parameter"] for r in rows[2:]} <= {"none_a", "none_b", "weak"}
    assert all(r["significant"] == "no" for r in rows if r["parameter"].startswith("none"))
    assert set(RANKED_COLUMNS) <= set(rows[0])
    mins = [r["min_log10_p"] for r in rows]
    assert mins == sorted(mins)


def test_effects_leave_out_failed_runs_and_refuse_too_few():
    X, Y = _synthetic(n=20)
    Y[3] = np.nan
    assert fit_parameter_effects(X, Y, PARAMS).n == 19
    with pytest.raises(EstimationError, match=r"parameter effects: 4 usable runs for 4 factors; need at least 6"):
        fit_parameter_effects(X[:5], Y[:5], PARAMS)
    X[:, 2] = 1.0
    with pytest.raises(EstimationError, match=r"factor\(s\) none_a do not vary"):
        fit_parameter_effects(X, Y, PARAMS)


def test_factors_and_dotted_keys():
    base = {"filter": {"sigma_t_mm": 0.02, "k_force_t": 0.0, "resampler": "systematic"}, "seed": 0}
    f = make_factors(base, ["filter.sigma_t_mm"], spread=0.5)
    assert f == (Factor("filter.sigma_t_mm", 0.01, 0.03),)
    assert make_factors(base, ["filter.sigma_t_mm"], ranges={"filter.k_force_t": (0.0, 1e-5)})[1] == \
        Factor("filter.k_force_t", 0.0, 1e-5)
    with pytest.raises(ConfigError, match=r"study factor 'filter.k_force_t': its base value is 0"):
        make_factors(base, ["filter.k_force_t"])
    with pytest.raises(ConfigError, match=r"study factor 'filter.nope': no such configuration key"):
        make_factors(base, ["filter.nope"])
    with pytest.raises(ConfigError, match=r"study factor 'filter.resampler': expected a numeric parameter"):
        make_factors(base, ["filter.resampler"])
    with pytest.raises(ConfigError, match=r"expected a range low < high, got \[2, 1\]"):
        Factor("a", 2.0, 1.0)
    d = {"a": {"b": 1}}
    set_dotted(d, "a.b", 5)
    assert get_dotted(d, "a.b") == 5
    assert ERROR_NAMES == ("rmse_x_mm", "rmse_y_mm", "rmse_z_mm", "rmse_rx_deg", "rmse_ry_deg", "rmse_rz_deg")
