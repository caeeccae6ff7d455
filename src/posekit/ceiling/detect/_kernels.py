"""Compiled kernels of the laser-dot detector (:mod:`posekit.ceiling.detect`): the lit-pixel scan,
the background update of one band of rows in one pass, the per-blob table (area, shape, the
light it adds, weighted centroid and moments) and the ring test of a blob's surroundings."""

import math

import numpy as np

from posekit._jit import njit

__all__ = ["_AREA", "_ELONG", "_MUU", "_MUV", "_MVV", "_PEAK", "_ADD_B", "_ADD_G", "_ADD_R", "_CLIPPED", "_OWN", "_U", "_V", "_VAR_UV",
           "_blob_table", "_lit_pixels", "_update_band", "_thresholds", "_ring_outliers", "_outlier_rate"]


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


@njit(cache=True, boundscheck=False, fastmath=True)
def _bar_of(v, z, v_scene, floor):
    """The bar of one byte: ``max(z sqrt(v + v_scene), floor)``, as the uint8 it is stored in
    (at least 1)."""
    b = z * math.sqrt(v + v_scene)
    if b < floor:
        b = floor
    b = math.floor(b + 0.5)
    return np.uint8(min(max(b, 1.0), 255.0))


@njit(cache=True, boundscheck=False, fastmath=True)
def _thresholds(var, bgu, baru, thr, r0, r1, z, v_scene, floor):
    """Rows r0:r1 of the bar (uint8) and of ``thr = min(mean + bar, 255)`` from the variance;
    (H, 3 W) views."""
    for i in range(r0, r1):
        for k in range(var.shape[1]):
            b = _bar_of(var[i, k], z, v_scene, floor)
            baru[i, k] = b
            thr[i, k] = np.uint8(min(np.int32(bgu[i, k]) + np.int32(b), 255))


@njit(cache=True, boundscheck=False, fastmath=True)
def _update_bytes(frame, bg, var, bgu, baru, thr, guessed, i, k0, k1, mode, alpha, alpha_out, z, v_scene, floor):
    """Bytes k0:k1 (whole pixels) of row i of :func:`_update_band`, all in one ``mode`` (0: plain,
    2: absorbed); float32 arithmetic, no branch on the byte (a select), so the loop vectorises."""
    z32 = np.float32(z)
    vs = np.float32(v_scene)
    fl = np.float32(max(floor, 1.0))
    a_in = np.float32(alpha)
    a_out = np.float32(alpha_out)
    absorbed = mode == 2                      # every byte an inlier
    for j in range(k0 // 3, k1 // 3):
        if guessed[i, j] > 0:
            guessed[i, j] -= 1
    for k in range(k0, k1):
        fi = np.int32(frame[i, k])
        f = np.float32(fi)
        m = bg[i, k]
        v0 = var[i, k]
        d = f - m
        b = np.float32(baru[i, k])
        inl = absorbed or abs(fi - np.int32(bgu[i, k])) <= np.int32(baru[i, k])
        a = a_in if inl else a_out
        dev2 = d * d if inl else b * b
        m = m + a * d
        v = v0 + a * (dev2 - v0)
        bg[i, k] = m
        var[i, k] = v
        mu = min(max(np.int32(m + np.float32(0.5)), 0), 255)
        bgu[i, k] = np.uint8(mu)
        bb = min(max(z32 * np.sqrt(v + vs), fl), np.float32(255.0))
        bi = np.int32(bb + np.float32(0.5))
        baru[i, k] = np.uint8(bi)
        thr[i, k] = np.uint8(min(mu + bi, 255))


@njit(cache=True, boundscheck=False, fastmath=True)
def _update_band(frame, bg, var, bgu, baru, thr, r0, r1, alpha, alpha_out, z, v_scene, floor, rects, only_rects,
                 guessed):
    """One pass over rows r0:r1 of the running mean and variance of every byte, then of the
    rounded mean, the bar and the threshold (all (H, 3 W) views; ``frame``, ``bgu``, ``baru``,
    ``thr`` uint8, ``bg``, ``var`` float32).

    A byte within its bar of the (rounded) mean is an inlier: mean and variance follow it at
    rate ``alpha``. An outlier (foreground: a person, a car, a dot) moves them at
    ``alpha_out``, its squared deviation counted as the bar's square (censored: it tells only
    that the byte left its bar). ``rects`` (R, 5) int: rows y0:y1, columns x0:x1 and a mode,
    1 = protected (left as it is: the tracked dot), 2 = absorbed (every byte an inlier: a
    static light of the scene becomes background). With ``only_rects`` the bytes outside every
    rectangle are left as they are. ``guessed`` (H, W) uint8: updates still to come before a
    pixel whose background was guessed (:func:`_ring_outliers` ignores it) counts as known;
    decremented at each update of the pixel.
    """
    n_rect = rects.shape[0]
    w3 = frame.shape[1]
    for i in range(r0, r1):
        active = 0
        for r in range(n_rect):
            if rects[r, 0] <= i < rects[r, 1]:
                active += 1
        if not active:
            if not only_rects:                   # no rectangle on this row: one tight loop
                _update_bytes(frame, bg, var, bgu, baru, thr, guessed, i, 0, w3, 0, alpha, alpha_out, z, v_scene,
                              floor)
            continue
        k = 0
        while k < w3:                            # runs of bytes of one mode
            j = k // 3
            mode = 0
            nxt = w3                             # where the mode may change next (a rectangle's edge), bytes
            for r in range(n_rect):
                if rects[r, 0] <= i < rects[r, 1]:
                    if rects[r, 2] <= j < rects[r, 3]:
                        mode = rects[r, 4]
                        nxt = min(nxt, 3 * rects[r, 3])
                    elif j < rects[r, 2]:
                        nxt = min(nxt, 3 * rects[r, 2])
                    else:
                        pass
            k1 = max(min(nxt, w3), k + 3)
            if not (mode == 1 or (only_rects and mode == 0)):
                _update_bytes(frame, bg, var, bgu, baru, thr, guessed, i, k, k1, mode, alpha, alpha_out, z,
                              v_scene, floor)
            k = k1


@njit(cache=True, boundscheck=False)
def _outlier_rate(frame, bgu, baru, step):
    """The scene's rate of background outliers where the background is unchanged: on a sparse
    grid (every ``step``-th row and column), the fraction of pixels beyond their bar (some
    channel, either side) in each cell of 4 × 4 grid points, and the median over the cells
    (the cells a car or a person covers are a minority: they do not count). ``frame``,
    ``bgu``, ``baru`` (H, W, 3) uint8."""
    h, w = frame.shape[0], frame.shape[1]
    ny, nx = (h - step // 2 + step - 1) // step, (w - step // 2 + step - 1) // step
    cy, cx = (ny + 3) // 4, (nx + 3) // 4
    cnt = np.zeros(cy * cx)
    tot = np.zeros(cy * cx)
    for a in range(ny):
        i = step // 2 + a * step
        for b in range(nx):
            j = step // 2 + b * step
            c = (a // 4) * cx + b // 4
            tot[c] += 1
            for ch in range(3):
                if abs(np.int32(frame[i, j, ch]) - np.int32(bgu[i, j, ch])) > baru[i, j, ch]:
                    cnt[c] += 1
                    break
    rates = np.empty(cy * cx)
    m = 0
    for c in range(cy * cx):
        if tot[c] >= 8:
            rates[m] = cnt[c] / tot[c]
            m += 1
    if m == 0:
        return 0.0
    return float(np.median(rates[:m]))


@njit(cache=True, boundscheck=False)
def _pixel_out(frame, bgu, baru, i, j, luma):
    """True if pixel (i, j) is beyond its bar, either side: in luma (``0.114 ΔB + 0.587 ΔG +
    0.299 ΔR`` against the same mix of the channels' bars) or in any channel."""
    if luma:
        dy = 0.0
        by = 0.0
        for c in range(3):
            wc = 0.114 if c == 0 else (0.587 if c == 1 else 0.299)
            dy += wc * (np.float64(frame[i, j, c]) - np.float64(bgu[i, j, c]))
            by += wc * np.float64(baru[i, j, c])
        return abs(dy) > by
    for c in range(3):
        if abs(np.int32(frame[i, j, c]) - np.int32(bgu[i, j, c])) > baru[i, j, c]:
            return True
    return False


@njit(cache=True, boundscheck=False)
def _ring_outliers(frame, bgu, baru, guessed, y0, y1, x0, x1, block):
    """The surroundings of a blob whose bounding box is rows y0:y1, columns x0:x1, block by block,
    as a codec leaves them: the ringing of a small bright spot stays inside the ``block``-pixel
    luma blocks it lies in (and its colour inside chroma blocks twice that size, 4:2:0, where
    only the luma is tested: ``0.114 ΔB + 0.587 ΔG + 0.299 ΔR`` against the same mix of the
    channels' bars), and what a codec leaves around a moving spot (motion-compensation residue)
    is a scatter of pixels, while an object — a car, a person — fills blocks. The ring is the
    blocks around the spot's blocks; a block is foreground when more than half of its pixels
    are beyond their bar. Returns (blocks in the ring, foreground blocks). ``frame``, ``bgu``,
    ``baru`` (H, W, 3); pixels whose background is still a guess (``guessed`` (H, W) > 0) are
    left out (a block with fewer than half its pixels left is not counted)."""
    h, w = frame.shape[0], frame.shape[1]
    b2 = 2 * block
    iy0, ix0 = (y0 // block) * block, (x0 // block) * block               # the spot's luma blocks
    iy1, ix1 = ((y1 - 1) // block + 1) * block, ((x1 - 1) // block + 1) * block
    cy0, cx0 = (y0 // b2) * b2, (x0 // b2) * b2                           # its chroma blocks
    cy1, cx1 = ((y1 - 1) // b2 + 1) * b2, ((x1 - 1) // b2 + 1) * b2
    n = 0
    out = 0
    for by0 in range(iy0 - block, iy1 + block, block):
        for bx0 in range(ix0 - block, ix1 + block, block):
            if iy0 <= by0 < iy1 and ix0 <= bx0 < ix1:
                continue
            n_px = 0
            n_out = 0
            for i in range(max(by0, 0), min(by0 + block, h)):
                for j in range(max(bx0, 0), min(bx0 + block, w)):
                    if guessed[i, j] > 0:
                        continue
                    n_px += 1
                    if _pixel_out(frame, bgu, baru, i, j, cy0 <= i < cy1 and cx0 <= j < cx1):
                        n_out += 1
            if 2 * n_px >= block * block:
                n += 1
                if 4 * n_out > n_px:
                    out += 1
    return n, out


@njit(cache=True, boundscheck=False)
def _share(f, b, white):
    """Light added to a byte (``f - b``, positive part) as a share of the headroom ``white - b``
    it had, in [0, 1] (a byte whose background is at the white level has none: 0)."""
    room = np.float64(white) - b
    if room <= 1.0:
        return 0.0
    return min(max((np.float64(f) - b) / room, 0.0), 1.0)


#: Columns of the per-blob table computed by :func:`_blob_table`: area, elongation, weighted
#: centroid, peak, weighted central second moments (uu, vv, uv; px²), the variance of the
#: centroid per axis that the background's own noise gives (px²), the light the blob adds in
#: each channel (B, G, R: the share of each byte's headroom to the white level that it took,
#: summed over the blob's weighted pixels that are not clipped in every channel), then
#: the pixels of the blob's window whose background is at the white level in some channel
#: (there the spot's light is cut: its centroid is pulled away from them), then per colour the
#: largest value of its own channel in the blob (the laser's channel: R for red).
_AREA, _ELONG, _U, _V, _PEAK, _MUU, _MVV, _MUV, _VAR_UV, _ADD_B, _ADD_G, _ADD_R, _CLIPPED, _OWN = range(14)


@njit(cache=True, boundscheck=False)
def _blob_table(frame, bg, var, labels, stats, n, own, white, margin, weight_threshold):
    """Per blob 1..n-1 of ``labels`` (a window of the frame): area, elongation, weighted
    centroid (u, v in window pixels; each pixel weighs its summed positive difference to the
    background less ``max(weight_threshold, 3σ)``, σ that sum's own noise, so flickering
    texture under the window does not pull it), peak, moments, the centroid's variance from
    the background noise (``Σ (x − ū)² Var(w) / W²`` averaged over the two axes, ``var`` the
    per-byte background variance), the light added per channel as a share of the headroom it
    had (``(f - b) / (white - b)`` in [0, 1], summed over the weighted pixels whose channels are
    not all clipped at ``white``: a clipped pixel tells nothing of the colour, every channel
    was cut) and, per colour of ``own`` ((k,) channel index 0-2), the
    largest value of that channel over the blob's pixels."""
    h, w = labels.shape
    k_col = own.shape[0]
    out = np.zeros((n, _OWN + k_col))
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
            for c in range(k_col):
                out[lab, _OWN + c] = max(out[lab, _OWN + c], np.float64(frame[i, j, own[c]]))
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
        ab = 0.0
        ag = 0.0
        ar = 0.0
        clipped = 0
        for i in range(y0, y1):
            for j in range(x0, x1):
                if bg[i, j, 0] >= white or bg[i, j, 1] >= white or bg[i, j, 2] >= white:
                    clipped += 1
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
                    if frame[i, j, 0] < white or frame[i, j, 1] < white or frame[i, j, 2] < white:
                        # each channel's added light as a share of the headroom it had left
                        # (a channel near the white level cannot show much light, whatever its colour)
                        ab += _share(frame[i, j, 0], bg[i, j, 0], white)
                        ag += _share(frame[i, j, 1], bg[i, j, 1], white)
                        ar += _share(frame[i, j, 2], bg[i, j, 2], white)
        out[lab, _PEAK] = peak
        out[lab, _ADD_B], out[lab, _ADD_G], out[lab, _ADD_R] = ab, ag, ar
        out[lab, _CLIPPED] = clipped
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
