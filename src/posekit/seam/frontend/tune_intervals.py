"""Honest uncertainty for ``posekit seam tune`` from the laser innovations (:mod:`.tune`): the joint 1σ of the
walk and noise, and a profile-likelihood interval per latency that says when the walk can stand in for it.

**Walk and laser noise.** The 1σ of each (log) value is the square root of the diagonal of the inverse of the
negative log-likelihood's *full* Hessian over every fitted parameter at once (central differences), not the
curvature along one parameter with the others held (which is too small where parameters trade off), and at least
the cluster-robust sandwich ``H⁻¹ (Σ_e g_e g_eᵀ) H⁻¹`` over the episodes' own gradients ``g_e`` (a misspecified
model's curvature is over-confident; the episodes' disagreement is not).

**Latency.** A latency ``L`` shifts each reading along the seam by ``L ṁ``; a robot error that wanders sideways
with the seam does the same, and the filter's random walk is its only model of that error. So each sensor's
latency gets its profile likelihood over a grid (0-50 ms): at every grid value the other parameters (walk, noise,
the other sensors' latencies) are optimised again, and the 95 % likelihood-ratio interval is where the profile is
within ``χ²₁(0.95) / 2 = 1.92`` of its minimum. It is computed twice, with the walk as fitted and with it
:data:`WALK_SCALE` times larger (a robot error that agile; noise and latencies re-optimised), and the interval
reported is the union: a latency that the walk's size moves is confounded with it, and the likelihood alone,
which trusts the random-walk model, would pin it confidently wrong (measured on tests/seam/independent_cell.py:
its latency of 13 ms profiled to [0, 3] ms with the walk as fitted, to [0, 22] ms with it ten times larger).
The latency is pinned only when that interval is inside the grid, off 0, and no wider than
``±`` :data:`LATENCY_HALF_WIDTH_S` (what the filter needs: at 45 mm/s a 5 ms error moves a reading 0.2 mm).
"""

import math

import numpy as np
from scipy.optimize import minimize

__all__ = ["CHI2_1_95", "LATENCY_GRID_S", "LATENCY_HALF_WIDTH_S", "WALK_SCALE", "LatencyInterval",
           "joint_std", "latency_interval", "reading_rate_rms", "score_edge", "uniform_rms"]

#: The 95 % quantile of χ² with one degree of freedom (the likelihood-ratio interval: half of it in log-likelihood).
CHI2_1_95 = 3.841458820694124
#: The latencies the profile likelihood is evaluated at (s).
LATENCY_GRID_S = np.arange(0.0, 0.0501, 0.005)
#: A latency is pinned when its interval is no wider than ± this (s).
LATENCY_HALF_WIDTH_S = 0.005
#: The second walk the latency's interval is computed with, as a multiple of the fitted one (a sensitivity:
#: a chosen constant, not fitted; see the module docstring).
WALK_SCALE = 10.0


def _gradient_and_hessian(fe, x, steps, free):
    """``Σ_e fe`` 's Hessian over ``free`` and each episode's gradient there (central differences)."""
    n = len(free)
    H = np.empty((n, n))
    f0 = fe(x)
    G = np.empty((f0.size, n))
    cache = {}

    def at(*moves):
        key = tuple(sorted(moves))
        if key not in cache:
            xx = x.copy()
            for i, s in moves:
                xx[free[i]] += s * steps[free[i]]
            cache[key] = fe(xx)
        return cache[key]

    for i in range(n):
        fp, fm = at((i, 1)), at((i, -1))
        G[:, i] = (fp - fm) / (2.0 * steps[free[i]])
        H[i, i] = (fp.sum() - 2.0 * f0.sum() + fm.sum()) / steps[free[i]] ** 2
        for j in range(i):
            H[i, j] = H[j, i] = (at((i, 1), (j, 1)).sum() - at((i, 1), (j, -1)).sum() - at((i, -1), (j, 1)).sum()
                                 + at((i, -1), (j, -1)).sum()) / (4.0 * steps[free[i]] * steps[free[j]])
    return G, H


def joint_std(fe, x: np.ndarray, steps: np.ndarray, free) -> np.ndarray:
    """1σ of each parameter in ``free`` from the full Hessian of ``Σ_e fe(x)_e`` and the episodes' gradients.

    Parameters
    ----------
    fe : callable
        ``x -> (E,)`` negative log-likelihood per episode.
    x : ndarray, shape (n,)
        The optimum.
    steps : ndarray, shape (n,)
        Central-difference steps.
    free : sequence of int
        The parameters the Hessian spans (the others held: at a bound, or profiled separately).

    Returns
    -------
    ndarray, shape (n,)
        ``max(√diag(H⁻¹), √diag(H⁻¹ G H⁻¹))`` on ``free`` (``G = Σ_e g_e g_eᵀ``), inf where the likelihood does
        not curve (a non-positive direction touching the parameter) and for the others.
    """
    free = list(free)
    out = np.full(x.size, np.inf)
    if not free:
        return out
    G, H = _gradient_and_hessian(fe, x, steps, free)
    if not (np.isfinite(H).all() and np.isfinite(G).all()):
        return out
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    ok = lam > 1e-9 * max(1.0, float(np.abs(lam).max()))
    Hi = (V[:, ok] / lam[ok]) @ V[:, ok].T
    var = np.maximum(np.diag(Hi), np.diag(Hi @ (G.T @ G) @ Hi))
    flat = np.abs(V[:, ~ok]).max(axis=1) > 0.1 if (~ok).any() else np.zeros(len(free), bool)
    out[free] = np.where(flat | ~(var > 0.0), np.inf, np.sqrt(np.clip(var, 0.0, None)))
    return out


class LatencyInterval:
    """One latency's 95 % profile-likelihood interval (s) under each walk, their union, and the verdict.

    Attributes
    ----------
    lo, hi : float
        The union of the intervals (s).
    by_walk : dict
        ``{walk scale: (lo, hi)}``.
    others : dict
        ``{other fitted latency's index: (least, largest)}`` over the profile's grid points inside the interval
        (how far the other sensors' latencies move along with this one).
    pinned : bool
    reason : str
        Why not pinned ('' when pinned).
    """

    def __init__(self, by_walk: dict, others: dict, grid_hi: float):
        self.by_walk = by_walk
        self.lo = min(v[0] for v in by_walk.values())
        self.hi = max(v[1] for v in by_walk.values())
        self.others = others
        self.grid_hi = grid_hi
        self.carried: list = []
        self._judge()

    def _judge(self) -> None:
        why = []
        if self.lo <= 0.0:
            why.append("touches 0")
        if self.hi >= self.grid_hi:
            why.append(f"reaches the grid's end {self.grid_hi * 1e3:.0f} ms")
        if self.hi - self.lo > 2.0 * LATENCY_HALF_WIDTH_S:
            why.append(f"wider than ±{LATENCY_HALF_WIDTH_S * 1e3:.0f} ms")
        (l1, h1) = self.by_walk[1.0]
        (lk, hk) = self.by_walk[WALK_SCALE]
        if max(l1, lk) > min(h1, hk):
            why.append(f"the walk moves it ({l1 * 1e3:.1f}-{h1 * 1e3:.1f} ms as fitted, {lk * 1e3:.1f}-"
                       f"{hk * 1e3:.1f} ms with the walk x{WALK_SCALE:g}): confounded with the lateral and yaw walk")
        self.pinned = not why
        self.reason = "; ".join(why + self.carried) if why else ""

    def carry(self, lo: float, hi: float, why: str) -> bool:
        """Widen the interval to ``[lo, hi]`` (the values this latency takes along another, not pinned latency's
        interval: the joint region's shadow) and judge again; returns whether it changed."""
        if lo >= self.lo and hi <= self.hi:
            return False
        self.lo, self.hi = min(self.lo, lo), max(self.hi, hi)
        self.carried.append(why)
        self._judge()
        return True

    @property
    def std(self) -> float:
        """A 1σ for the report: the interval's half width over 1.96."""
        return (self.hi - self.lo) / (2.0 * 1.959963984540054)


def _point(f, start, free, i, L, maxfev):
    """The profile at ``x[i] = L``: the least ``f`` over ``free`` from ``start``; returns (value, solution)."""
    cur = start.copy()
    cur[i] = L

    def h(z):
        xx = cur.copy()
        xx[free] = z
        return f(xx)

    r = minimize(h, cur[free], method="Nelder-Mead",
                 options={"maxfev": maxfev * len(free), "xatol": 1e-3, "fatol": 1e-2, "adaptive": True})
    cur[free] = r.x
    return float(r.fun), cur


def _vertex(L, v):
    """The vertex of the parabola through the smallest point and its neighbours when it lies strictly between
    them (the grid is coarse: the profile is evaluated there too), else None."""
    k = int(np.argmin(v))
    if not (0 < k < len(v) - 1 and np.all(np.isfinite(v[k - 1:k + 2]))):
        return None
    (a, b, c), (fa, fb, fc) = L[k - 1:k + 2], v[k - 1:k + 2]
    den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
    if den == 0.0:
        return None
    t = b - 0.5 * ((b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)) / den
    return float(t) if a < t < c and min(t - a, c - t, abs(t - b)) > 1e-4 else None


def _edge(f, free, i, maxfev, inside, outside, lim, bisect):
    """Where the profile crosses ``lim`` between an ``inside`` and an ``outside`` point ``(L, value, solution)``:
    ``bisect`` halvings, then linearly (a convex profile's chord alone would put it too near the minimum)."""
    for _ in range(bisect):
        L = 0.5 * (inside[0] + outside[0])
        v, sol = _point(f, inside[2], free, i, L, maxfev)
        if v <= lim:
            inside = (L, v, sol)
        else:
            outside = (L, v, sol)
    if not np.isfinite(outside[1]):
        return inside[0], inside[2]
    t = (lim - inside[1]) / (outside[1] - inside[1])
    return inside[0] + (outside[0] - inside[0]) * t, inside[2]


def latency_interval(f, x: np.ndarray, i: int, lat_idx, walk_idx, grid=None, maxfev: int = 15,
                     bisect: int = 3):
    """Profile-likelihood interval of parameter ``x[i]`` (a latency, s) under the walk as fitted and ×
    :data:`WALK_SCALE` (see the module docstring).

    Parameters
    ----------
    f : callable
        ``x -> float``, the negative log-likelihood (inf outside the bounds).
    x : ndarray, shape (n,)
        The joint optimum; ``x[walk_idx]`` are the logs of the walk.
    i : int
        The latency examined.
    lat_idx : sequence of int
        Every fitted latency's index (the others are re-optimised with the rest).
    walk_idx : sequence of int
        The log-walk parameters.
    grid : ndarray, optional
        The latencies (s; default :data:`LATENCY_GRID_S`).
    maxfev : int
        Nelder-Mead evaluations per free parameter at each profile point (warm-started from the neighbour).
    bisect : int
        Halvings of the grid step at each end of the interval.

    Returns
    -------
    LatencyInterval
    """
    grid = np.asarray(LATENCY_GRID_S if grid is None else grid, dtype=np.float64)
    by_walk, others = {}, {}
    drop = CHI2_1_95 / 2.0
    for scale in (1.0, WALK_SCALE):
        base = x.copy()
        if scale != 1.0:
            base[list(walk_idx)] += math.log(scale)
        free = [j for j in range(x.size) if j != i and (scale == 1.0 or j not in walk_idx)]
        pts = [None] * grid.size
        start = int(np.argmin(np.abs(grid - x[i])))
        for order in (range(start, grid.size), range(start - 1, -1, -1)):
            cur = base
            for g in order:
                v, cur = _point(f, cur, free, i, grid[g], maxfev)
                pts[g] = (float(grid[g]), v, cur)
        if scale == 1.0:  # the joint optimum is a point of this profile too
            pts.append((float(x[i]), float(f(x)), x.copy()))
            pts.sort(key=lambda p: p[0])
        t = _vertex(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]))
        if t is not None:
            near = min(pts, key=lambda p: abs(p[0] - t))
            v, sol = _point(f, near[2], free, i, t, maxfev)
            pts.append((t, v, sol))
            pts.sort(key=lambda p: p[0])
        vals = np.array([p[1] for p in pts])
        lim = float(np.min(vals)) + drop
        inside = np.flatnonzero(vals <= lim)
        a, b = int(inside[0]), int(inside[-1])
        lo = pts[0][0] if a == 0 else _edge(f, free, i, maxfev, pts[a], pts[a - 1], lim, bisect)[0]
        hi = pts[-1][0] if b == len(pts) - 1 else _edge(f, free, i, maxfev, pts[b], pts[b + 1], lim, bisect)[0]
        by_walk[scale] = (float(lo), float(hi))
        for j in lat_idx:
            if j != i:
                v = [p[2][j] for p in pts[a:b + 1]]
                lo_j, hi_j = others.get(j, (np.inf, -np.inf))
                others[j] = (min(lo_j, float(min(v))), max(hi_j, float(max(v))))
    return LatencyInterval(by_walk, others, float(grid[-1]))


def score_edge(total, x: np.ndarray, a: int, side: float, level: float, bounds: tuple[float, float]) -> float:
    """The log walk along axis ``a`` (others at ``x``), from ``x[a]`` towards ``side`` (-1 narrower, +1 wider), where
    ``total`` first reaches ``level`` (steps of e, then bisection to 0.01 in the log); the bound ``bounds`` (low, high)
    on that side where it never does. A slice (the others held), unlike :func:`latency_interval`'s profile."""
    xx = x.copy()
    inside = float(x[a])
    while True:
        outside = float(np.clip(inside + side, *bounds))
        if outside == inside:
            return inside
        xx[a] = outside
        if total(xx) >= level:
            break
        inside = outside
    while abs(outside - inside) > 0.01:
        xx[a] = 0.5 * (inside + outside)
        if total(xx) >= level:
            outside = xx[a]
        else:
            inside = xx[a]
    return 0.5 * (inside + outside)


def uniform_rms(a: float, b: float) -> float:
    """The rms of ``u`` uniform over ``[a, b]``."""
    return math.sqrt(max((a * a + a * b + b * b) / 3.0, 0.0))


def reading_rate_rms(eps, sensor: int | None, half: int = 5) -> float:
    """The rms rate of the laser readings (mm/s, both in-plane components), from differences over ``2 half``
    samples (the noise's share small); ``sensor`` None pools every sensor.

    Parameters
    ----------
    eps : sequence of LinearisedEpisode
        Their ``laser (T, S, 2)`` and ``data.time_s``.
    sensor : int or None
    half : int
    """
    acc, n = 0.0, 0
    for e in eps:
        m = e.laser if sensor is None else e.laser[:, sensor:sensor + 1]
        t = np.asarray(e.data.time_s, dtype=np.float64)
        if t.size <= 2 * half:
            continue
        rate = (m[2 * half:] - m[:-2 * half]) / (t[2 * half:] - t[:-2 * half])[:, None, None]
        r2 = np.sum(rate * rate, axis=-1)
        r2 = r2[np.isfinite(r2)]
        acc += float(r2.sum())
        n += r2.size
    return math.sqrt(acc / n) if n else 0.0
