"""Scale drift of a monocular trajectory: a per-segment scale test.

A monocular VO/SLAM trajectory has an unknown scale, and its scale drifts as it goes (1–3 % over
a path is common). One similarity fit then averages a scale that holds nowhere along the path.
:func:`scale_drift` measures it:

1. the matched pairs, in time order, are cut into ``K`` consecutive segments of about equal
   length along the dst path (``K`` between 3 and :data:`MAX_SEGMENTS`, at least
   :data:`MIN_SEGMENT_PAIRS` pairs each);
2. in every segment the scale is fitted with the global rotation held and the segment's own
   translation (``s_k = Σ (R a_i)·b_i / Σ |a_i|²`` on the segment's centred positions), with its
   variance from the segment's residuals times their integrated autocorrelation time;
3. a weighted straight line ``s(u) = α + β u`` through the segment scales over the position ``u``
   (0 at the start of the path, 1 at its end, by dst path length) gives the drift ``β / α``, the
   relative change of scale along the path, with its 1σ from the weighted least squares.

The drift is significant when ``|β/α| / σ`` exceeds the two-sided normal quantile of
:data:`SCALE_ALPHA`: a significance level and the reported variance set the threshold, nothing
is tuned on a simulator.
"""

from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from posekit._autocorr import autocorrelation_time

__all__ = ["MAX_SEGMENTS", "MIN_SEGMENT_PAIRS", "SCALE_ALPHA", "ScaleDrift", "scale_drift"]

#: Significance level of the drift test (two-sided).
SCALE_ALPHA = 0.01
#: Fewest pairs per segment (a scale from fewer is mostly noise).
MIN_SEGMENT_PAIRS = 10
#: Most segments (more only thin each segment's lever).
MAX_SEGMENTS = 8


@dataclass(frozen=True)
class ScaleDrift:
    """The per-segment scale test.

    Attributes
    ----------
    relative : float
        ``β / α``: relative change of the scale from the start to the end of the path (0.02 = the
        scale at the end is 2 % larger than at the start).
    std : float
        1σ of ``relative``.
    segments : int
        Number of segments.
    segment_scales : ndarray, shape (K,)
        The scale fitted in each segment.
    significant : bool
        ``|relative| / std`` beyond the ``SCALE_ALPHA`` two-sided normal quantile.
    """

    relative: float
    std: float
    segments: int
    segment_scales: np.ndarray
    significant: bool

    def to_json(self) -> dict:
        """``{"relative", "std", "segments", "segment_scales"}``."""
        def f(v):
            return float(v) if np.isfinite(v) else None
        return {"relative": f(self.relative), "std": f(self.std), "segments": int(self.segments),
                "segment_scales": [f(v) for v in self.segment_scales]}


def scale_drift(p_src, p_dst, R, *, alpha: float = SCALE_ALPHA) -> ScaleDrift | None:
    """The per-segment scale test of a similarity match (module docstring).

    Parameters
    ----------
    p_src : ndarray, shape (N, 3)
        Paired src positions in time order, src world frame, mm (any unit: only ratios matter).
    p_dst : ndarray, shape (N, 3)
        Paired dst positions, base frame, mm.
    R : ndarray, shape (3, 3)
        The fitted ``R_dst_src``.
    alpha : float
        Significance level of the test.

    Returns
    -------
    ScaleDrift or None
        None when there are fewer than ``3 * MIN_SEGMENT_PAIRS`` pairs or the path does not move
        within the segments.
    """
    p_src = np.asarray(p_src, dtype=np.float64)
    p_dst = np.asarray(p_dst, dtype=np.float64)
    n = len(p_src)
    k = int(min(MAX_SEGMENTS, n // MIN_SEGMENT_PAIRS))
    if k < 3:
        return None
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p_dst, axis=0), axis=1))]
    if arc[-1] <= 0:
        return None
    u = arc / arc[-1]
    # equal path length per segment, each with at least MIN_SEGMENT_PAIRS pairs
    bounds = np.r_[0, np.searchsorted(u, np.linspace(0.0, 1.0, k + 1)[1:-1]), n]
    for i in range(1, k):                                   # each segment at least MIN_SEGMENT_PAIRS long
        bounds[i] = max(bounds[i], bounds[i - 1] + MIN_SEGMENT_PAIRS)
    for i in range(k - 1, 0, -1):
        bounds[i] = min(bounds[i], bounds[i + 1] - MIN_SEGMENT_PAIRS)
    scales, variances, centres = [], [], []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        a = p_src[lo:hi] @ R.T
        b = p_dst[lo:hi]
        a = a - a.mean(0)
        b = b - b.mean(0)
        aa = float((a ** 2).sum())
        if aa <= 0 or hi - lo < MIN_SEGMENT_PAIRS:
            return None
        s_k = float((a * b).sum()) / aa
        r = b - s_k * a
        var = float((r ** 2).sum()) / max(3 * (hi - lo) - 4, 1) / aa * autocorrelation_time(r)
        scales.append(s_k)
        variances.append(max(var, 1e-300))
        centres.append(0.5 * (u[lo] + u[hi - 1]))
    s_k, w, x = np.array(scales), 1.0 / np.array(variances), np.array(centres)
    X = np.column_stack([np.ones(k), x])
    cov = np.linalg.inv(X.T @ (X * w[:, None]))
    alpha_hat, beta = cov @ (X.T @ (w * s_k))
    # the weights are the reported variances: scale them up when the segments scatter more
    chi2 = float((w * (s_k - X @ [alpha_hat, beta]) ** 2).sum())
    cov = cov * max(1.0, chi2 / max(k - 2, 1))
    rel = beta / alpha_hat
    # delta method for beta / alpha
    g = np.array([-beta / alpha_hat ** 2, 1.0 / alpha_hat])
    std = float(np.sqrt(max(g @ cov @ g, 0.0)))
    z = abs(rel) / std if std > 0 else np.inf
    return ScaleDrift(float(rel), std, k, s_k, bool(z > NormalDist().inv_cdf(1.0 - alpha / 2.0)))
