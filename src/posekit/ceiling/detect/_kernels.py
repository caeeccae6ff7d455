"""Compiled kernels of the laser-dot detector (:mod:`posekit.ceiling.detect`): the lit-pixel scan
and the per-blob table (area, shape, colour counts, weighted centroid and moments)."""

import math

import numpy as np

from posekit._jit import njit

__all__ = ["_AREA", "_COUNTS", "_ELONG", "_MUU", "_MUV", "_MVV", "_PEAK", "_PLAIN", "_U", "_V", "_VAR_UV",
           "_blob_table", "_lit_pixels"]


@njit(cache=True, boundscheck=False)
def _lit_pixels(frame, thr, y0, y1, x0, x1, coords):
    """Pixels in rows y0:y1, columns x0:x1 where any channel of ``frame`` exceeds ``thr``.

    ``frame`` and ``thr`` are (H, 3 W) uint8 views. Writes (row, col) into ``coords`` up to
    its length and returns how many there are (which may exceed it).
    """
    n = 0
    cap = coords.shape[0]
    for i in range(y0, y1):
        f = frame[i, 3 * x0:3 * x1]
        t = thr[i, 3 * x0:3 * x1]
        acc = np.uint8(0)
        for k in range(f.shape[0]):                 # vectorised: no lit byte, no second pass
            acc = max(acc, np.uint8(max(np.int16(f[k]) - np.int16(t[k]), 0) > 0))
        if acc:
            last = -1
            for k in range(f.shape[0]):
                if f[k] > t[k]:
                    j = x0 + k // 3
                    if j != last:
                        if n < cap:
                            coords[n, 0] = i
                            coords[n, 1] = j
                        n += 1
                        last = j
    return n


#: Columns of the per-blob table computed by :func:`_blob_table`: area, elongation, weighted
#: centroid, peak, unsaturated pixels, weighted central second moments (uu, vv, uv; px²), the
#: variance of the centroid per axis that the background's own noise gives (px²), then one
#: count per colour.
_AREA, _ELONG, _U, _V, _PEAK, _PLAIN, _MUU, _MVV, _MUV, _VAR_UV, _COUNTS = range(11)


@njit(cache=True, boundscheck=False)
def _blob_table(frame, bg, var, labels, stats, n, specs, core_level, margin, weight_threshold):
    """Per blob 1..n-1 of ``labels`` (a window of the frame): area, elongation, weighted
    centroid (u, v in window pixels; each pixel weighs its summed positive difference to the
    background less ``max(weight_threshold, 3σ)``, σ that sum's own noise, so flickering
    texture under the window does not pull it), peak, number of unsaturated pixels, the centroid's
    variance from the background noise (``Σ (x − ū)² Var(w) / W²`` averaged over the two
    axes, ``var`` the per-byte background variance) and, per colour of ``specs`` ((k, 3): hue
    lo, hue hi in degrees, min saturation), how many of those have it."""
    h, w = labels.shape
    k_col = specs.shape[0]
    out = np.zeros((n, _COUNTS + k_col))
    mom = np.zeros((n, 5))                       # sum x, y, xx, yy, xy over the blob's pixels
    for i in range(h):
        for j in range(w):
            lab = labels[i, j]
            if lab == 0:
                continue
            mom[lab, 0] += j
            mom[lab, 1] += i
            mom[lab, 2] += j * j
            mom[lab, 3] += i * i
            mom[lab, 4] += i * j
            if frame[i, j, 0] >= core_level and frame[i, j, 1] >= core_level and frame[i, j, 2] >= core_level:
                continue                            # saturated core: no colour
            b = max(np.float64(frame[i, j, 0]) - bg[i, j, 0], 0.0)
            g = max(np.float64(frame[i, j, 1]) - bg[i, j, 1], 0.0)
            r = max(np.float64(frame[i, j, 2]) - bg[i, j, 2], 0.0)
            mx = max(r, max(g, b))
            mn = min(r, min(g, b))
            out[lab, _PLAIN] += 1
            if mx <= 0.0:
                continue
            span = mx - mn
            sat = span / mx
            if span <= 0.0:
                hue = 0.0
            elif mx == r:
                hue = 60.0 * (((g - b) / span) % 6.0)
            elif mx == g:
                hue = 60.0 * ((b - r) / span + 2.0)
            else:
                hue = 60.0 * ((r - g) / span + 4.0)
            for c in range(k_col):
                lo, hi = specs[c, 0], specs[c, 1]
                inside = (lo <= hue <= hi) if lo <= hi else (hue >= lo or hue <= hi)
                if inside and sat >= specs[c, 2]:
                    out[lab, _COUNTS + c] += 1
    for lab in range(1, n):
        a = stats[lab, 4]
        out[lab, _AREA] = a
        mx, my = mom[lab, 0] / a, mom[lab, 1] / a
        sxx = mom[lab, 2] / a - mx * mx + 1.0 / 12.0          # + the extent of a pixel
        syy = mom[lab, 3] / a - my * my + 1.0 / 12.0
        sxy = mom[lab, 4] / a - mx * my
        tr, det = sxx + syy, sxx * syy - sxy * sxy
        disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
        l1, l2 = tr / 2.0 + disc, tr / 2.0 - disc
        out[lab, _ELONG] = math.sqrt(l1 / l2) if l2 > 0 else np.inf
        y0, y1 = max(stats[lab, 1] - margin, 0), min(stats[lab, 1] + stats[lab, 3] + margin, h)
        x0, x1 = max(stats[lab, 0] - margin, 0), min(stats[lab, 0] + stats[lab, 2] + margin, w)
        sw = 0.0
        su = 0.0
        sv = 0.0
        suu = 0.0
        svv = 0.0
        suv = 0.0
        peak = 0.0
        for i in range(y0, y1):
            for j in range(x0, x1):
                s = 0.0
                vs = 0.0
                for c in range(3):
                    s += max(np.float64(frame[i, j, c]) - bg[i, j, c], 0.0)
                    vs += var[i, j, c]
                peak = max(peak, s)
                wt = s - max(weight_threshold, 3.0 * math.sqrt(vs))     # within the pixel's own noise: no weight
                if wt > 0.0:
                    sw += wt
                    su += wt * j
                    sv += wt * i
                    suu += wt * j * j
                    svv += wt * i * i
                    suv += wt * i * j
        out[lab, _PEAK] = peak
        if sw > 0:
            u, v = su / sw, sv / sw
            out[lab, _U], out[lab, _V] = u, v
            out[lab, _MUU], out[lab, _MVV], out[lab, _MUV] = suu / sw - u * u, svv / sw - v * v, suv / sw - u * v
            acc = 0.0
            for i in range(y0, y1):
                for j in range(x0, x1):
                    s = 0.0
                    vs = 0.0
                    for c in range(3):
                        s += max(np.float64(frame[i, j, c]) - bg[i, j, c], 0.0)
                        vs += var[i, j, c]
                    if s - max(weight_threshold, 3.0 * math.sqrt(vs)) > 0.0:
                        acc += 0.5 * ((j - u) ** 2 + (i - v) ** 2) * vs
            out[lab, _VAR_UV] = acc / (sw * sw)
        else:
            out[lab, _U] = out[lab, _V] = np.nan
    return out
