"""Corner detection in a laser profile of a multi-plane gauge (paper §II-D).

Two compiled detectors share this interface (corners (n, 2) in F, mm, with their joint
covariance):

* **model-based** (``detect_corners(profile, gauge)``, or ``gauge=``): uses the gauge's
  cross-section, so it survives real profiles — rounded or chamfered ridges, the mounting
  plate and fixtures beside the gauge, multipath clusters, objects on a face, dropouts.
  The profile is cut into straight segments, the segments are assigned to the faces by the
  gauge's order and turns (the rest is left unassigned), each face is fitted away from
  the rounded zones and neighbours are intersected: :mod:`~posekit.profiler.estimate.segments`,
  :mod:`~posekit.profiler.estimate.faces`. About 17 µs for 3,200 points of an ideal profile,
  25 µs with a plate and a fixture in view (``posekit bench profiler``).
* **RDP** (``detect_corners(profile, n_corners)``): knows only the number of corners; the
  paper's pipeline, exact on ideal profiles (below). An extra or missing RDP vertex is an
  error.

RDP pipeline, compiled as one numba kernel (about 15 µs for 3,200 points):

1. Drop missing returns (NaN) and isolated spikes: a point farther than ``spike_mm`` in
   z from the median of its 5 neighbours in scan order is an outlier.
2. Corner candidates by Ramer–Douglas–Peucker, taken in order of decreasing deviation
   until the gauge's known number of corners ``n`` is reached: the ``n``-th candidate
   must deviate at least ``min_corner_mm`` from its chord (else a corner is missing) and
   no further vertex may (else there is an extra corner). This is RDP with the tolerance
   set between the ``n``-th and ``(n+1)``-th deviation.
3. Each of the ``n + 1`` segments between candidates loses ``trim`` (10 %) of its points
   at both ends (edge effects of laser triangulation), and the rest is fitted by an
   orthogonal (TLS) line with iterative rejection of residuals beyond 4 RMS, so spikes
   too small for step 1 and short dropouts inside a segment do not bias it.
4. Corner k is the intersection of the lines of segments k and k + 1. Its 2×2
   covariance follows from the fit: each line's perpendicular offset at the corner has
   variance ``σ² (1/N + τ²/S_tt)`` (σ the residual RMS, τ the corner's distance from the
   segment centroid along the line, S_tt the points' spread along the line).
"""

import weakref
from dataclasses import dataclass

import numpy as np

from posekit._jit import njit

from ...errors import ProfileError
from ...geometry import robust_line_kernel
from ..gauge.model import Gauge
from . import faces
from .corner_params import CornerParams, param_vector
from .face_fit import corner_jacobian_rows
from .segments import _median5, chord_deviation, expected_turns

__all__ = ["Corners", "detect_corners", "detect_corners_unchecked", "check_profile",
           "raise_for_status", "gauge_turns"]

OK = 0
NO_POINTS = 1
MISSING = 2
EXTRA = 3
SHORT_SEGMENT = 4
PARALLEL = 5
NO_MATCH = faces.NO_MATCH
CLUTTER = faces.CLUTTER
EXTRA_FACE = faces.EXTRA_FACE


_TURNS = weakref.WeakKeyDictionary()


def gauge_turns(gauge: Gauge) -> np.ndarray:
    """The gauge's cross-section as the model detector uses it: the turn at each ridge, rad, (n,).

    Cached per gauge; pass it to :func:`detect_corners_unchecked` on the real-time path.
    See :func:`~posekit.profiler.estimate.segments.expected_turns`.
    """
    t = _TURNS.get(gauge)
    if t is None:
        t = np.ascontiguousarray(expected_turns(gauge))
        t.flags.writeable = False
        _TURNS[gauge] = t
    return t


@dataclass(frozen=True)
class Corners:
    """Corners found in one profile.

    Attributes
    ----------
    points : ndarray, shape (n, 2)
        Corner (x, z) in F, mm, in scan order.
    cov : ndarray, shape (2n, 2n)
        Joint covariance of the stacked corners ``[x0, z0, x1, z1, ...]``, mm².
        Neighbouring corners share a fitted line, so their errors are correlated.
    lines : ndarray, shape (n + 1, 3)
        Fitted face lines ``(nx, nz, c)`` with ``nx x + nz z = c`` in F.
    sigma : ndarray, shape (n + 1,)
        Residual RMS of each line fit, mm.
    n_points : ndarray of int, shape (n + 1,)
        Points each line was fitted on (after trimming and rejection).
    """

    points: np.ndarray
    cov: np.ndarray
    lines: np.ndarray
    sigma: np.ndarray
    n_points: np.ndarray


@njit(cache=True, nogil=True)
def _detect_kernel(profile, n, min_corner, spike, trim, k_sigma, min_pts, sigma_floor):
    """Returns (status, info, corners (n,2), cov (2n,2n), lines (n+1,3), sigma, npts, cand)."""
    corners = np.full((n, 2), np.nan)
    cov = np.full((2 * n, 2 * n), np.nan)
    lines = np.full((n + 1, 3), np.nan)
    sig = np.full(n + 1, np.nan)
    npts = np.zeros(n + 1, dtype=np.int64)
    cand = np.full((n + 1, 3), np.nan)       # candidate x, z, deviation (n+1-th: the extra one)
    info = np.zeros(4)

    # 1. Valid returns in scan order, then spike rejection against a 5-point running median.
    m_all = profile.shape[0]
    xs0 = np.empty(m_all)
    zs0 = np.empty(m_all)
    m0 = 0
    for i in range(m_all):
        x = profile[i, 0]
        z = profile[i, 1]
        if np.isfinite(x) and np.isfinite(z):
            xs0[m0] = x
            zs0[m0] = z
            m0 += 1
    info[1] = m0
    if m0 < (n + 1) * min_pts:
        return NO_POINTS, info, corners, cov, lines, sig, npts, cand
    xs = np.empty(m0)
    zs = np.empty(m0)
    m = 0
    for i in range(m0):
        a = max(0, min(i - 2, m0 - 5))
        med = _median5(zs0[a], zs0[a + 1], zs0[a + 2], zs0[a + 3], zs0[a + 4])
        if abs(zs0[i] - med) <= spike:
            xs[m] = xs0[i]
            zs[m] = zs0[i]
            m += 1
    info[2] = m0 - m
    if m < (n + 1) * min_pts:
        return NO_POINTS, info, corners, cov, lines, sig, npts, cand

    # 2. RDP candidates in order of decreasing deviation.
    verts = np.empty(n + 2, dtype=np.int64)
    verts[0] = 0
    verts[1] = m - 1
    nv = 2
    seg_dev = np.empty(n + 1)
    seg_arg = np.empty(n + 1, dtype=np.int64)
    stride = max(1, m // 512)
    seg_dev[0], seg_arg[0] = chord_deviation(xs, zs, 0, m - 1, stride, False)
    for k in range(n + 1):
        best = 0
        for s in range(1, nv - 1):
            if seg_dev[s] > seg_dev[best]:
                best = s
        if k == n:
            if seg_dev[best] >= min_corner:
                j = seg_arg[best]
                cand[n, 0] = xs[j]
                cand[n, 1] = zs[j]
                cand[n, 2] = seg_dev[best]
                info[0] = n + 1
                return EXTRA, info, corners, cov, lines, sig, npts, cand
            break
        if seg_dev[best] < min_corner:
            info[0] = k
            for s in range(1, nv - 1):
                cand[s - 1, 0] = xs[verts[s]]
                cand[s - 1, 1] = zs[verts[s]]
            info[3] = xs[0]
            cand[n, 0] = xs[0]
            cand[n, 1] = xs[m - 1]
            return MISSING, info, corners, cov, lines, sig, npts, cand
        j = seg_arg[best]
        # insert vertex j after position best
        for s in range(nv, best + 1, -1):
            verts[s] = verts[s - 1]
        for s in range(nv - 1, best + 1, -1):
            seg_dev[s] = seg_dev[s - 1]
            seg_arg[s] = seg_arg[s - 1]
        verts[best + 1] = j
        nv += 1
        seg_dev[best], seg_arg[best] = chord_deviation(xs, zs, verts[best], j, stride, False)
        seg_dev[best + 1], seg_arg[best + 1] = chord_deviation(xs, zs, j, verts[best + 2], stride, False)
    info[0] = n
    for s in range(1, nv - 1):
        cand[s - 1, 0] = xs[verts[s]]
        cand[s - 1, 1] = zs[verts[s]]
        cand[s - 1, 2] = 0.0

    # 3. Trimmed robust line fit of each segment.
    cent = np.empty((n + 1, 3))              # centroid x, z and spread S_tt of each fit
    for s in range(n + 1):
        i0 = verts[s]
        i1 = verts[s + 1]
        cut = int(np.ceil(trim * (i1 - i0)))
        a = i0 + cut
        b = i1 - cut + 1
        if b - a < min_pts:
            npts[s] = max(b - a, 0)
            info[3] = s
            return SHORT_SEGMENT, info, corners, cov, lines, sig, npts, cand
        nx, nz, c, mx, mz, sw, s_tt, rms = robust_line_kernel(xs, zs, a, b, 4, k_sigma, 1e-4)
        npts[s] = int(sw)
        if sw < min_pts:
            info[3] = s
            return SHORT_SEGMENT, info, corners, cov, lines, sig, npts, cand
        lines[s, 0] = nx
        lines[s, 1] = nz
        lines[s, 2] = c
        sig[s] = max(rms * np.sqrt(sw / max(sw - 2.0, 1.0)), sigma_floor)
        cent[s, 0] = mx
        cent[s, 1] = mz
        cent[s, 2] = s_tt

    # 4. Corners as intersections of neighbouring lines, with their joint covariance.
    # Line j's error is an offset δc_j (var σ²/N) and a turn δθ_j about its centroid
    # (var σ²/S_tt), independent. At a point τ along the line from the centroid it moves
    # by δc_j + τ δθ_j along its normal; corner k solves N_k δp = [δ_k, δ_k+1].
    G = np.zeros((2 * n, 2 * (n + 1)))       # corner errors = G @ [δc_0, δθ_0, δc_1, ...]
    for k in range(n):
        ax = lines[k, 0]
        az = lines[k, 1]
        ac = lines[k, 2]
        bx = lines[k + 1, 0]
        bz = lines[k + 1, 1]
        bc = lines[k + 1, 2]
        det = ax * bz - az * bx
        if abs(det) < 1e-9:
            info[3] = k
            return PARALLEL, info, corners, cov, lines, sig, npts, cand
        px = (ac * bz - bc * az) / det
        pz = (ax * bc - bx * ac) / det
        corners[k, 0] = px
        corners[k, 1] = pz
        corner_jacobian_rows(G, k, px, pz, cent, ax, az, bx, bz, det)
    var = np.empty(2 * (n + 1))
    for j in range(n + 1):
        var[2 * j] = sig[j] ** 2 / npts[j]
        var[2 * j + 1] = sig[j] ** 2 / max(cent[j, 2], 1e-300)
    for a in range(2 * n):
        for b in range(a, 2 * n):
            acc = 0.0
            for c in range(2 * (a // 2), 2 * (a // 2) + 4):
                acc += G[a, c] * var[c] * G[b, c]
            cov[a, b] = acc
            cov[b, a] = acc
    return OK, info, corners, cov, lines, sig, npts, cand


def detect_corners_unchecked(profile, n_corners, params=CornerParams(), turns=None):
    """Run a compiled detector on a (N, 2) float64 C-contiguous profile; no validation.

    With ``turns`` (the gauge's cross-section, :func:`gauge_turns`, shape (n_corners,)) the
    model-based detector runs (n_corners is then ``len(turns)``), else the RDP detector.
    Returns the raw tuple
    ``(status, info, corners, cov, lines, sigma, n_points, cand)``; ``status == 0`` means
    success. For the real-time path; use :func:`detect_corners` otherwise.
    """
    if turns is not None:
        return faces.model_kernel(profile, turns, param_vector(params))
    return _detect_kernel(profile, n_corners, params.min_corner_mm, params.spike_mm, params.trim,
                          params.k_sigma, params.min_segment_points, params.sigma_floor_mm)


def _fmt_x(values):
    return "[" + ", ".join(f"{v:.1f}" for v in values) + "]"


#: Largest relative misfit of the distances between found corners and a run of the gauge's ridges
#: for the corners to be part of that gauge. Measured on the bundled gauges (6 poses each, one or two
#: corners cut away): the right gauge fits within 0.17, demo-5/demo-7 profiles against demo-10 miss by 0.30-0.56.
WRONG_GAUGE_MISFIT = 0.25
#: Returns (mm, along x) beyond a missing ridge that still count as "not in view" (its rounded edge, noise).
WRONG_GAUGE_MARGIN_MM = 2.0


def wrong_gauge_reason(corners_xz, span_x, gauge: Gauge) -> str | None:
    """Why the corners found cannot belong to ``gauge`` with some of its corners out of view, or None.

    The corners found must be pierce points of a run of consecutive ridges: their distances match
    the ridges' (at some y, stretched by at most 10 % for a turned laser line) within
    :data:`WRONG_GAUGE_MISFIT`, and each ridge outside the run lies beyond the returns (else it
    would have been seen).

    Parameters
    ----------
    corners_xz : ndarray, shape (F, 2)
        Corners found, in scan order, (x, z) in F, mm; F < gauge.n_corners.
    span_x : tuple of float
        x of the first and the last return of the profile, mm.
    gauge : Gauge

    Returns
    -------
    str or None
        The reason, naming the gauge, when no run of its ridges explains the corners.
    """
    c = np.asarray(corners_xz, dtype=float)
    found, n = len(c), gauge.n_corners
    if found < 3 or found >= n:
        return None
    d = np.linalg.norm(np.diff(c, axis=0), axis=1)
    ext = (abs(c[0, 0] - span_x[0]), abs(span_x[1] - c[-1, 0]))      # returns beyond the outer corners
    ys = np.linspace(gauge.y_range[0], gauge.y_range[1], 41)
    P = gauge.ridge_q[None] + ys[:, None, None] * gauge.ridge_s[None]  # ridge points at each y, (Y, n, 3)
    D = np.linalg.norm(np.diff(P, axis=1), axis=2)                     # ridge-to-ridge distances, (Y, n-1)
    Dx = np.abs(np.diff(P[..., 0], axis=1))
    for k in range(n - found + 1):
        W = D[:, k:k + found - 1]
        for rev, dd in ((False, d), (True, d[::-1])):
            scale = np.clip((W * dd).sum(1) / (W * W).sum(1), 1.0, 1.1)
            fits = (np.abs(dd - scale[:, None] * W) / W).max(1) <= WRONG_GAUGE_MISFIT
            before = Dx[:, k - 1] * scale if k > 0 else np.full(len(ys), np.inf)
            after = Dx[:, k + found - 1] * scale if k + found - 1 < n - 1 else np.full(len(ys), np.inf)
            left, right = (after, before) if rev else (before, after)
            hidden = (left > ext[0] - WRONG_GAUGE_MARGIN_MM) & (right > ext[1] - WRONG_GAUGE_MARGIN_MM)
            if np.any(fits & hidden):
                return None
    return (f"the {found} corners found fit no {found} consecutive ridges of gauge '{gauge.name}' with the rest out "
            f"of view (the returns span x = {span_x[0]:.1f}..{span_x[1]:.1f} mm): wrong gauge file?")


def raise_for_status(status, info, npts, cand, n_corners, gauge_name="gauge", gauge: Gauge | None = None):
    """Turn a failed kernel status into a :class:`ProfileError` that says what went wrong.

    With ``gauge``, missing corners that no run of its ridges explains are called a wrong gauge
    (:func:`wrong_gauge_reason`) instead of corners out of view."""
    what = f"expected {n_corners} corners for gauge '{gauge_name}'"
    if status == NO_POINTS:
        if info[1] == 0:
            raise ProfileError("profile has no valid points (every return is NaN)")
        raise ProfileError(
            f"{what}, but the profile has only {int(info[1])} valid points "
            f"({int(info[2])} rejected as spikes); the gauge is not in view"
        )
    if status == MISSING:
        found = int(info[0])
        where = _fmt_x(cand[:found, 0]) if found else "none"
        wrong = None if gauge is None else wrong_gauge_reason(cand[:found, :2], cand[n_corners, :2], gauge)
        if wrong is not None:
            raise ProfileError(f"{what}, found {found} (at x = {where} mm); {wrong}")
        raise ProfileError(
            f"{what}, found {found} (at x = {where} mm); missing corner(s): the returns span "
            f"x = {cand[n_corners, 0]:.1f}..{cand[n_corners, 1]:.1f} mm, so part of the gauge is "
            "out of the measuring range or occluded"
        )
    if status == EXTRA:
        raise ProfileError(
            f"{what}, found an extra corner at x = {cand[n_corners, 0]:.2f} mm, "
            f"z = {cand[n_corners, 1]:.2f} mm ({cand[n_corners, 2]:.2f} mm off the faces); "
            "wrong gauge file, or an object in the laser line"
        )
    if status == SHORT_SEGMENT:
        s = int(info[3])
        raise ProfileError(
            f"{what}: face {s} has only {int(npts[s])} usable points after trimming "
            f"(expected >= {CornerParams.min_segment_points}); the face is too short in the profile"
        )
    if status == PARALLEL:
        k = int(info[3])
        raise ProfileError(f"{what}: the lines of faces {k} and {k + 1} are parallel in the profile; "
                           f"corner {k} is undefined")
    if status == NO_MATCH:
        raise ProfileError(
            f"{what}: no {n_corners + 1} of the profile's {int(info[0])} straight segments turn like "
            "the gauge's faces (ridges and valleys in order, each face meeting the next); wrong gauge "
            "file, or part of the gauge is hidden"
        )
    if status == EXTRA_FACE:
        raise ProfileError(
            f"{what}, found an extra corner at x = {cand[n_corners, 0]:.2f} mm, z = {cand[n_corners, 1]:.2f} mm "
            f"(a face turning {cand[n_corners, 2]:.0f} deg continues the gauge past its outer face); "
            "wrong gauge file, or an object against the gauge"
        )
    if status == CLUTTER:
        raise ProfileError(
            f"{what}: the profile breaks into more than {int(info[7])} straight segments; "
            "it is not a gauge (or far noisier than a laser profiler)"
        )
    raise ProfileError(f"corner detection failed with status {status}")


def check_profile(profile, name="profile"):
    """Validate a single profile: array-like (N, 2) of floats; returns float64 C-contiguous."""
    try:
        arr = np.ascontiguousarray(profile, dtype=np.float64)
    except (TypeError, ValueError):
        raise ProfileError(f"{name}: expected an array of (x, z) points in mm, got non-numeric data") from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ProfileError(f"{name}: expected shape (N, 2) of (x, z) points in mm, got {arr.shape}")
    if arr.shape[0] == 0:
        raise ProfileError(f"{name}: profile is empty; expected (x, z) points in mm")
    if np.any(np.isinf(arr)):
        raise ProfileError(f"{name}: profile holds infinite values; use NaN for no return")
    return arr


def detect_corners(profile, n_corners, params=CornerParams(), gauge_name="gauge", gauge=None):
    """Find the gauge's corners in one laser profile.

    Parameters
    ----------
    profile : array_like, shape (N, 2)
        Points (x, z) in the profiler frame F, mm, in scan order; NaN = no return.
    n_corners : int or Gauge
        Number of corners of the gauge (its ridges): the RDP detector. A :class:`Gauge`
        runs the model-based detector (the same as ``gauge=``).
    params : CornerParams, optional
    gauge_name : str, optional
        Used in error messages (default: the gauge's name when one is given).
    gauge : Gauge, optional
        The gauge: corners by its cross-section (real profiles: rounded edges, plates and
        fixtures in view, multipath, ...).

    Returns
    -------
    Corners
        Corners in scan order.

    Raises
    ------
    ProfileError
        If the profile has no usable points, a corner is missing or extra (RDP) or no
        segments match the gauge's faces (model), or a face is too short to fit; the
        message says which.
    """
    if isinstance(n_corners, Gauge):
        gauge = n_corners
    turns = None
    if gauge is not None:
        if not isinstance(n_corners, Gauge) and int(n_corners) != gauge.n_corners:
            raise ProfileError(f"n_corners = {n_corners} does not match gauge '{gauge.name}' "
                               f"({gauge.n_corners} corners)")
        n_corners = gauge.n_corners
        turns = gauge_turns(gauge)
        if gauge_name == "gauge":
            gauge_name = gauge.name
    arr = check_profile(profile)
    status, info, corners, cov, lines, sig, npts, cand = detect_corners_unchecked(
        arr, int(n_corners), params, turns)
    if status != OK:
        raise_for_status(status, info, npts, cand, n_corners, gauge_name, gauge)
    return Corners(points=corners, cov=cov, lines=lines, sigma=sig, n_points=npts)
