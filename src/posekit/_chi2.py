"""The χ² distribution's tail probability and quantiles, in plain Python (``math``).

The consistency tests need ``chi2.isf``, ``chi2.sf`` and ``chi2.median``. Importing
``scipy.stats`` for them costs about a second at every start of the command line (its ~100
distributions are built at import) and ``scipy.special`` 0.15-1 s (its array-API layer);
these few lines cost nothing. :data:`chi2` answers the same calls with scipy.stats' argument
order; the tests cross-check it against ``scipy.stats.chi2`` to 1e-10.

The tail is the regularized upper incomplete gamma function Q(df/2, x/2), by its series
below x = a + 1 and by its continued fraction (modified Lentz) above (Numerical Recipes
§6.2); the quantile is Newton's method on log Q from the Wilson-Hilferty start.
"""

import math
from statistics import NormalDist
from types import SimpleNamespace

import numpy as np

__all__ = ["chi2"]

_EPS = 1e-16
_TINY = 1e-300
_MAX_TERMS = 100_000


def _log_prefactor(a: float, x: float) -> float:
    """log(x^a e^-x / Γ(a))."""
    return a * math.log(x) - x - math.lgamma(a)


def _upper_gamma(a: float, x: float) -> float:
    """Q(a, x) = Γ(a, x) / Γ(a), a > 0, x >= 0."""
    if x <= 0.0:
        return 1.0
    if x < a + 1.0:                        # series for P, then Q = 1 - P
        term = total = 1.0 / a
        ap = a
        for _ in range(_MAX_TERMS):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * _EPS:
                break
        return max(1.0 - total * math.exp(_log_prefactor(a, x)), 0.0)
    b = x + 1.0 - a                        # continued fraction for Q (modified Lentz)
    c = 1.0 / _TINY
    d = 1.0 / b
    h = d
    for i in range(1, _MAX_TERMS):
        b += 2.0
        d, c, step = lentz_step(d, c, -i * (i - a), b)
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return math.exp(_log_prefactor(a, x)) * h


def lentz_step(d: float, c: float, a: float, b: float) -> tuple[float, float, float]:
    """One step of the modified Lentz method for a continued fraction ``... a / (b + ...)``: the new ``d`` and
    ``c`` and the factor ``d c`` the running value is multiplied by (Numerical Recipes §5.2)."""
    d = a * d + b
    d = _TINY if abs(d) < _TINY else d
    c = b + a / c
    c = _TINY if abs(c) < _TINY else c
    d = 1.0 / d
    return d, c, d * c


def _sf1(x: float, df: float) -> float:
    if not (df > 0 and math.isfinite(df)) or math.isnan(x):
        return math.nan
    return 1.0 if x <= 0 else (0.0 if math.isinf(x) else _upper_gamma(0.5 * df, 0.5 * x))


def _isf1(q: float, df: float) -> float:
    if not (df > 0 and math.isfinite(df)) or not (0.0 <= q <= 1.0):
        return math.nan
    if q == 0.0:
        return math.inf
    if q == 1.0:
        return 0.0
    a = 0.5 * df
    z = -NormalDist().inv_cdf(q)
    h = 2.0 / (9.0 * df)
    x = max(df * (1.0 - h + z * math.sqrt(h)) ** 3, 1e-8 * df)   # Wilson-Hilferty start
    log_q = math.log(q)
    lo, hi = 0.0, math.inf
    for _ in range(200):
        sf = _upper_gamma(a, 0.5 * x)
        if sf > q:
            lo = x
        else:
            hi = x
        if sf <= 0.0:                      # far in the tail: step back towards the bracket
            x = 0.5 * (lo + x) if math.isinf(hi) or lo > 0 else 0.5 * x
            continue
        # d log Q / dx = -pdf(x) / Q(x), pdf of χ²(df) at x
        log_pdf = (a - 1.0) * math.log(0.5 * x) - 0.5 * x - math.lgamma(a) - math.log(2.0)
        step = (math.log(sf) - log_q) / math.exp(log_pdf - math.log(sf))
        new = x + step
        if not (lo < new < hi):            # Newton left the bracket: bisect instead
            new = 0.5 * (lo + hi) if math.isfinite(hi) else 2.0 * x
        if abs(new - x) <= 1e-13 * max(x, 1e-300):
            return new
        x = new
    return x


_isf = np.frompyfunc(_isf1, 2, 1)
_sf = np.frompyfunc(_sf1, 2, 1)


def _float(out):
    return out.astype(float) if isinstance(out, np.ndarray) else np.float64(out)


#: ``chi2.isf(q, df)``, ``chi2.sf(x, df)``, ``chi2.median(df)`` as ``scipy.stats.chi2`` gives
#: them (NumPy floats or arrays, broadcast over their arguments).
chi2 = SimpleNamespace(
    isf=lambda q, df: _float(_isf(q, df)),
    sf=lambda x, df: _float(_sf(x, df)),
    median=lambda df: _float(_isf(0.5, df)),
)
