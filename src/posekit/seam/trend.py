"""l1 trend filtering of a 3-D path (paper eq. 10): a piecewise-affine approximation.

::

    minimize_z  ||y - z||_F^2 + lam * sum_i sum_j |z_ij - 2 z_i+1,j + z_i+2,j|
    subject to  ||y - z||_inf <= eps

The non-zero second differences ``w`` are the knots of the approximation; the polyline through
the knots is what the laser density searches for the laser-plane/seam intersection (§II-E),
tens of segments instead of hundreds of trajectory points. Solved with cvxpy + Clarabel
(OSQP stops unconverged on this problem; see DESIGN.md); the status is checked.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import EstimationError

__all__ = ["KNOT_TOL", "TrendResult", "trend_filter"]

#: A second difference larger than this (relative to the path's extent) marks a knot.
KNOT_TOL = 1e-6


@dataclass(frozen=True)
class TrendResult:
    """Result of :func:`trend_filter`.

    Attributes
    ----------
    z : ndarray, shape (N, 3)
        The piecewise-affine approximation of ``y``, same frame and unit (mm).
    knots : ndarray of int, shape (K,)
        Indices into ``y`` of the polyline vertices: the first and last point and every
        point where the second difference of ``z`` is non-zero (sorted).
    polyline : ndarray, shape (K, 3)
        ``z[knots]``: the knot polyline (mm).
    max_error_mm : float
        ``max |y - z|`` over all points and coordinates (<= eps up to solver tolerance).
    status : str
        The solver status ("optimal").
    """

    z: np.ndarray
    knots: np.ndarray
    polyline: np.ndarray
    max_error_mm: float
    status: str


def trend_filter(y, *, lam: float = 100.0, eps_mm: float = 0.02) -> TrendResult:
    """Piecewise-affine approximation of a path by l1 trend filtering (eq. 10).

    Parameters
    ----------
    y : array_like, shape (N, 3)
        Path points, e.g. nominal TCP positions in the robot base frame, mm. N >= 3.
    lam : float
        Weight ``λ >= 0`` of the l1 norm of the second differences (more: fewer knots).
    eps_mm : float
        Largest allowed deviation ``ε > 0`` per coordinate, mm.

    Returns
    -------
    TrendResult

    Raises
    ------
    EstimationError
        Bad shape or values, or the solver does not reach an optimal solution.

    Examples
    --------
    >>> y = np.c_[np.r_[0:10.0], np.abs(np.r_[0:10.0] - 4.0), np.zeros(10)]
    >>> trend_filter(y, lam=100.0, eps_mm=0.01).knots.tolist()
    [0, 4, 9]
    """
    import cvxpy as cp

    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2 or y.shape[1] != 3 or y.shape[0] < 3:
        raise EstimationError(f"trend filter: expected y of shape (N >= 3, 3), got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise EstimationError("trend filter: y has non-finite values")
    if not (np.isfinite(lam) and lam >= 0):
        raise EstimationError(f"trend filter: expected lam >= 0, got {lam}")
    if not (np.isfinite(eps_mm) and eps_mm > 0):
        raise EstimationError(f"trend filter: expected eps_mm > 0, got {eps_mm}")
    n = y.shape[0]
    # Centre and scale for the solver's sake; eps and lam are rescaled to match.
    centre = y.mean(axis=0)
    scale = max(float(np.abs(y - centre).max()), eps_mm)
    ys = (y - centre) / scale
    z = cp.Variable((n, 3))
    w = z[:-2] - 2 * z[1:-1] + z[2:]
    objective = cp.Minimize(cp.sum_squares(ys - z) + (lam / scale) * cp.sum(cp.abs(w)))
    problem = cp.Problem(objective, [cp.abs(ys - z) <= eps_mm / scale])
    try:
        problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:
        raise EstimationError(f"trend filter: Clarabel failed ({exc})") from None
    if problem.status != cp.OPTIMAL:
        raise EstimationError(
            f"trend filter: solver status '{problem.status}', expected 'optimal' "
            f"(N = {n}, lam = {lam:g}, eps = {eps_mm:g} mm)"
        )
    zs = np.asarray(z.value)
    w2 = zs[:-2] - 2 * zs[1:-1] + zs[2:]
    mask = np.abs(w2).max(axis=1) > KNOT_TOL
    knots = np.unique(np.concatenate([[0], np.flatnonzero(mask) + 1, [n - 1]]))
    z_mm = zs * scale + centre
    max_err = float(np.abs(y - z_mm).max())
    return TrendResult(z_mm, knots, z_mm[knots], max_err, str(problem.status))
