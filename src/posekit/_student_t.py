"""Student's t upper quantile in plain Python (``math``), for the same reason as :mod:`posekit._chi2`.

The seam integrity monitor's offset test needs ``t.isf(alpha, dof)`` for a non-integer ``dof`` (an effective
number of independent windows) when a tracker starts; ``scipy.stats`` costs about a second at every start of the
command line. The upper tail is ``sf(x) = I_{ν/(ν + x²)}(ν/2, 1/2) / 2`` with ``I`` the regularized incomplete
beta function, by its continued fraction (modified Lentz, Numerical Recipes §6.4); the quantile is bisection on
it. The tests cross-check both against ``scipy.stats.t``.
"""

import math

from posekit._chi2 import lentz_step

__all__ = ["t_isf", "t_sf"]

_EPS = 1e-15
_TINY = 1e-300
_MAX_TERMS = 10_000


def _beta_cf(a: float, b: float, x: float) -> float:
    """The continued fraction of the incomplete beta function (converges for x < (a + 1) / (a + b + 2))."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c = 1.0
    d = 1.0 - qab * x / qap
    d = _TINY if abs(d) < _TINY else d
    d = 1.0 / d
    h = d
    for m in range(1, _MAX_TERMS):
        m2 = 2 * m
        d, c, step = lentz_step(d, c, m * (b - m) * x / ((qam + m2) * (a + m2)), 1.0)
        h *= step
        d, c, step = lentz_step(d, c, -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)), 1.0)
        h *= step
        if abs(step - 1.0) < _EPS:
            break
    return h


def _beta_inc(a: float, b: float, x: float) -> float:
    """The regularized incomplete beta function ``I_x(a, b)``, ``0 <= x <= 1``."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_cf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_cf(b, a, 1.0 - x) / b


def t_sf(x: float, dof: float) -> float:
    """``P(T > x)`` for Student's t with ``dof > 0`` degrees of freedom (NaN for a bad ``dof`` or ``x``)."""
    if not (dof > 0.0 and math.isfinite(dof)) or math.isnan(x):
        return math.nan
    if math.isinf(x):
        return 0.0 if x > 0 else 1.0
    tail = 0.5 * _beta_inc(0.5 * dof, 0.5, dof / (dof + x * x))
    return tail if x >= 0.0 else 1.0 - tail


def t_isf(alpha: float, dof: float) -> float:
    """The ``x`` with ``P(T > x) = alpha`` for Student's t with ``dof`` degrees of freedom, ``0 < alpha < 1``
    (NaN outside), to a relative 1e-12."""
    if not (dof > 0.0 and math.isfinite(dof)) or not (0.0 < alpha < 1.0):
        return math.nan
    if alpha == 0.5:
        return 0.0
    if alpha > 0.5:
        return -t_isf(1.0 - alpha, dof)
    lo, hi = 0.0, 1.0
    while t_sf(hi, dof) > alpha:       # bracket: the tail falls monotonically
        lo, hi = hi, 2.0 * hi
        if hi > 1e300:
            return math.inf
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_sf(mid, dof) > alpha:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    return 0.5 * (lo + hi)
