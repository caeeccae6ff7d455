"""Small dense linear solves compiled with numba, for kernels that run in a hot loop.

``numpy.linalg`` cannot be called cheaply from inside a numba kernel step by step on a 6×6
system (each call allocates and dispatches); the Gauss–Newton refinement of the profiler and the
resolved-rate loop of the long-reach arm simulator both solve one such system per iteration.
"""

import math

from posekit._jit import njit

__all__ = ["cholesky_solve"]


@njit(cache=True, nogil=True)
def cholesky_solve(A, b, x, L, ridge=0.0):
    """Solve ``(A + ridge · diag(A)) x = b`` by Cholesky, in place.

    Parameters
    ----------
    A : ndarray, shape (n, n)
        Symmetric matrix (only the lower triangle is read).
    b : ndarray, shape (n,)
        Right-hand side.
    x : ndarray, shape (n,)
        Output: the solution (may not alias ``b``).
    L : ndarray, shape (n, n)
        Work array: the lower-triangular factor on return.
    ridge : float
        Levenberg–Marquardt damping: ``ridge · max(A_ii, 1e-30)`` is added to each diagonal
        element (0: plain Cholesky).

    Returns
    -------
    bool
        False if the (damped) matrix is not positive definite (``x`` is then undefined).
    """
    n = A.shape[0]
    for i in range(n):
        for j in range(i + 1):
            acc = A[i, j] + (ridge * max(A[i, i], 1e-30) if i == j else 0.0)
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if acc <= 0.0:
                    return False
                L[i, i] = math.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * x[k]
        x[i] = acc / L[i, i]
    for i in range(n - 1, -1, -1):
        acc = x[i]
        for k in range(i + 1, n):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return True
