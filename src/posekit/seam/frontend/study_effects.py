"""The statistics of the tuning study: a linear model of each error on the factors, and their ranking.

A linear model (statsmodels OLS, with an intercept) of each run's RMSE on the factor values gives
one p-value per factor and error; :func:`rank_parameters` orders the factors by their smallest
p-value.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from posekit._extras import require
from posekit.errors import ConfigError, EstimationError
from posekit.seam.frontend.report import ERROR_AXES
from posekit.seam.frontend.study_factors import Factor

__all__ = ["ALPHA", "ERROR_NAMES", "RANKED_COLUMNS", "ParameterEffects", "fit_parameter_effects", "rank_parameters"]

#: Names of the six responses (RMSE over all steps of a run's episodes).
ERROR_NAMES = tuple(f"rmse_{a}_{'mm' if i < 3 else 'deg'}" for i, a in enumerate(ERROR_AXES))
#: Significance level of the ``significant`` column (before the Bonferroni correction over errors).
ALPHA = 0.05


@dataclass
class ParameterEffects:
    """Linear models (OLS with intercept) of each error on the factors.

    Attributes
    ----------
    parameters : tuple of str, length P
    errors : tuple of str, length E
    coef : ndarray, shape (E, P)
        Slopes: change of the error (its unit) per unit of the factor.
    pvalues : ndarray, shape (E, P)
        Two-sided t-test p-values of the slopes.
    rsquared : ndarray, shape (E,)
    n : int
        Runs used in the fit.
    """

    parameters: tuple
    errors: tuple
    coef: np.ndarray
    pvalues: np.ndarray
    rsquared: np.ndarray
    n: int

    @property
    def log10_p(self) -> np.ndarray:
        """(E, P) log10 of the p-values (p = 0 is clipped to 1e-300)."""
        return np.log10(np.clip(self.pvalues, 1e-300, 1.0))


def fit_parameter_effects(X: np.ndarray, Y: np.ndarray, parameters: Sequence[str],
                          errors: Sequence[str] = ERROR_NAMES) -> ParameterEffects:
    """OLS of each column of ``Y`` on the columns of ``X`` (plus an intercept).

    Parameters
    ----------
    X : ndarray, shape (R, P)
        Factor values of each run (their config units).
    Y : ndarray, shape (R, E)
        Responses of each run (e.g. RMSE per error axis). Rows with a non-finite value in X
        or Y are left out of every model.
    parameters, errors : sequence of str
        Names of the P factors and E responses.

    Returns
    -------
    ParameterEffects

    Raises
    ------
    EstimationError
        Fewer than P + 2 usable runs, or a factor that does not vary.
    """
    sm = require("statsmodels.api", "studies", "the seam study's parameter effects (OLS)")

    X = np.asarray(X, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if X.ndim != 2 or Y.ndim != 2 or len(X) != len(Y) or X.shape[1] != len(parameters) or \
            Y.shape[1] != len(errors):
        raise ConfigError(f"parameter effects: expected X (R, {len(parameters)}) and Y (R, {len(errors)}), "
                          f"got {X.shape} and {Y.shape}")
    ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Y), axis=1)
    n, p = int(ok.sum()), X.shape[1]
    if n < p + 2:
        raise EstimationError(f"parameter effects: {n} usable runs for {p} factors; need at least {p + 2} "
                              f"(raise --runs)")
    Xo = X[ok]
    flat = [parameters[j] for j in range(p) if np.ptp(Xo[:, j]) == 0]
    if flat:
        raise EstimationError(f"parameter effects: factor(s) {', '.join(flat)} do not vary over the runs")
    design = sm.add_constant(Xo, has_constant="add")
    coef = np.empty((Y.shape[1], p))
    pv = np.empty((Y.shape[1], p))
    r2 = np.empty(Y.shape[1])
    for e in range(Y.shape[1]):
        fit = sm.OLS(Y[ok, e], design).fit()
        coef[e] = fit.params[1:]
        pv[e] = fit.pvalues[1:]
        r2[e] = fit.rsquared
    return ParameterEffects(tuple(parameters), tuple(errors), coef, pv, r2, n)


RANKED_COLUMNS = ("rank", "parameter", "low", "high", "min_log10_p", "most_affected", "significant",
                  *(f"log10_p_{a}" for a in ERROR_AXES),
                  *(f"range_effect_{a}_{'mm' if i < 3 else 'deg'}" for i, a in enumerate(ERROR_AXES)))


def rank_parameters(effects: ParameterEffects, factors: Sequence[Factor]) -> list[dict]:
    """Factors ordered by their smallest p-value over the errors (most significant first).

    Each row: ``rank`` (1 = matters most), ``parameter``, its range, ``min_log10_p``, the error
    it affects most (``most_affected``), ``significant`` (smallest p < 0.05 / E, Bonferroni
    over the E errors), the log10 p-value per error, and ``range_effect_*``: the change of each
    error's RMSE predicted over the factor's whole range (slope × (high - low)).
    """
    lp = effects.log10_p
    n_err = len(effects.errors)
    rows = []
    for j, f in enumerate(factors):
        col = lp[:, j]
        e = int(np.nanargmin(col)) if np.any(np.isfinite(col)) else 0
        row = {"parameter": f.name, "low": f.low, "high": f.high, "min_log10_p": float(col[e]),
               "most_affected": effects.errors[e],
               "significant": "yes" if col[e] < np.log10(ALPHA / n_err) else "no"}
        for i, a in enumerate(ERROR_AXES[:n_err]):
            row[f"log10_p_{a}"] = float(col[i])
            row[f"range_effect_{a}_{'mm' if i < 3 else 'deg'}"] = float(effects.coef[i, j] * (f.high - f.low))
        rows.append(row)
    rows.sort(key=lambda r: (r["min_log10_p"], r["parameter"]))
    for k, r in enumerate(rows, 1):
        r["rank"] = k
    return rows
