"""Integrated autocorrelation time of a time series (the factor by which correlated samples are worth fewer).

Shared by the systems that turn correlated residuals into honest variances: localcal's trajectory match
(:mod:`posekit.localcal.registration.uncertainty`) and seam's integrity calibration
(:mod:`posekit.seam.frontend.tune_nis`).
"""

import numpy as np

__all__ = ["autocorrelation_time"]

#: Lags computed directly (O(N) memory) before switching to an FFT over every lag.
_DIRECT_LAGS = 64
#: Autocorrelation below this ends the sum of the integrated autocorrelation time.
_RHO_CUT = 0.05


def autocorrelation_time(r) -> float:
    """Integrated autocorrelation time of residual sequences, >= 1.

    Parameters
    ----------
    r : ndarray, shape (N, D)
        Residuals in time order (each column a component).

    Returns
    -------
    float
        ``max`` over the columns of ``1 + 2 Σ_k ρ_k`` (k from 1 while ``ρ_k > 0.05``, at most
        N/4 lags), at least 1.
    """
    r = np.asarray(r, dtype=np.float64)
    if r.ndim == 1:
        r = r[:, None]
    n = len(r)
    if n < 8:
        return 1.0
    x = r - r.mean(0)
    var = (x ** 2).sum(0)
    max_lag = max(n // 4, 2)
    taus = []
    for k in range(r.shape[1]):
        if var[k] <= 0:
            continue
        xk = np.ascontiguousarray(x[:, k])
        rho = _acf_direct(xk, var[k], min(_DIRECT_LAGS, max_lag))
        below = np.flatnonzero(rho[1:] <= _RHO_CUT)
        if not below.size and len(rho) < max_lag:          # long correlation: every lag by FFT
            nfft = 1 << int(np.ceil(np.log2(2 * n)))
            f = np.fft.rfft(xk, nfft)
            rho = np.fft.irfft(f * np.conj(f), nfft)[:max_lag] / var[k]
            below = np.flatnonzero(rho[1:] <= _RHO_CUT)
        m = int(below[0]) + 1 if below.size else len(rho)
        taus.append(1.0 + 2.0 * float(rho[1:m].sum()))
    return max([1.0, *taus])


def _acf_direct(x, var, lags):
    """Autocorrelation of ``x`` at lags 0..lags-1, stopping after the first value <= _RHO_CUT."""
    rho = [1.0]
    for k in range(1, lags):
        rho.append(float(x[:-k] @ x[k:]) / var)
        if rho[-1] <= _RHO_CUT:
            break
    return np.array(rho)
