"""l1 trend filtering of a 3-D path (paper eq. 10): a piecewise-affine approximation.

::

    minimize_z  ||y - z||_F^2 + lam * sum_i sum_j |z_ij - 2 z_i+1,j + z_i+2,j|
    subject to  ||y - z||_inf <= eps

The non-zero second differences ``w`` are the knots of the approximation; the polyline through
the knots is what the laser density searches for the laser-plane/seam intersection (§II-E),
tens of segments instead of hundreds of trajectory points. Solved as a quadratic program with
Clarabel's own API (OSQP stops at its iteration limit unconverged on this problem, ~3 s for N = 1,000); the status is
checked. In the deviation ``u = z - y`` and with ``t >= |w|`` elementwise, the problem is,
per coordinate column,

::

    minimize_{u, t}  u'u + lam * 1't
    subject to       D u - t <= -D y,  -D u - t <= D y,  -eps <= u <= eps

with ``D`` the (N-2) x N second-difference matrix. Written in ``u`` (not ``z``) the optimal
objective is small, so Clarabel's relative gap tolerance is tight in absolute terms. The three
columns are independent; they are solved as one block-diagonal program.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import EstimationError

__all__ = ["KNOT_TOL", "TrendResult", "trend_filter"]

#: A second difference larger than this (relative to the path's extent) marks a knot.
KNOT_TOL = 1e-6

# Clarabel's status -> the name reported (cvxpy's names for the same outcomes).
_STATUS = {
    "Solved": "optimal",
    "AlmostSolved": "optimal_inaccurate",
    "PrimalInfeasible": "infeasible",
    "AlmostPrimalInfeasible": "infeasible_inaccurate",
    "DualInfeasible": "unbounded",
    "AlmostDualInfeasible": "unbounded_inaccurate",
    "MaxIterations": "user_limit",
    "MaxTime": "user_limit",
}


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
        The solver status ("optimal"; the names are cvxpy's, e.g. "user_limit" for Clarabel's
        MaxIterations).
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
    import clarabel
    import scipy.sparse as sp

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
    # x = [u = z - ys (3N, column by column), t (3(N-2))]; every constraint row is "A x <= b".
    nz, nt = 3 * n, 3 * (n - 2)
    second = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n), format="csc")
    D = sp.kron(sp.identity(3, format="csc"), second, format="csc")
    I_z = sp.identity(nz, format="csc")
    I_t = sp.identity(nt, format="csc")
    A = sp.vstack([
        sp.hstack([D, -I_t]),
        sp.hstack([-D, -I_t]),
        sp.hstack([I_z, sp.csc_matrix((nz, nt))]),
        sp.hstack([-I_z, sp.csc_matrix((nz, nt))]),
    ], format="csc")
    yv = ys.T.ravel()
    e = eps_mm / scale
    Dy = D @ yv
    b = np.concatenate([-Dy, Dy, np.full(2 * nz, e)])
    P = sp.block_diag([2.0 * I_z, sp.csc_matrix((nt, nt))], format="csc")    # upper triangular (diagonal)
    q = np.concatenate([np.zeros(nz), np.full(nt, lam / scale)])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    try:
        solution = clarabel.DefaultSolver(P, q, A, b, [clarabel.NonnegativeConeT(A.shape[0])], settings).solve()
    except Exception as exc:  # noqa: BLE001 -- Clarabel raises plain exceptions for bad data
        raise EstimationError(f"trend filter: Clarabel failed ({exc})") from None
    raw = str(solution.status)
    status = _STATUS.get(raw, f"solver_error ({raw})")
    if status != "optimal":
        raise EstimationError(
            f"trend filter: solver status '{status}', expected 'optimal' "
            f"(N = {n}, lam = {lam:g}, eps = {eps_mm:g} mm)"
        )
    zs = ys + np.asarray(solution.x[:nz]).reshape(3, n).T
    w2 = zs[:-2] - 2 * zs[1:-1] + zs[2:]
    mask = np.abs(w2).max(axis=1) > KNOT_TOL
    knots = np.unique(np.concatenate([[0], np.flatnonzero(mask) + 1, [n - 1]]))
    z_mm = zs * scale + centre
    max_err = float(np.abs(y - z_mm).max())
    return TrendResult(z_mm, knots, z_mm[knots], max_err, status)
