"""Rendering an as-built gauge (:mod:`~posekit.profiler.sim.realism`) as the sensor sees it.

First-hit ray casting of the LJ-X8400's fan at the as-built faces, their fillets (cylinders
tangent to both faces, cast exactly) and chamfers (planes), the mounting plate and the
fixture block; then what the sensor adds: multipath ghosts beside valleys, its scale error
and dropouts on steep surfaces. The sensor noise is added by
:func:`~posekit.profiler.sim.render.render_profiles`.
"""

import numpy as np

from posekit._jit import njit

from ..gauge.raycast import first_face_hit, ray_in_gauge

__all__ = ["true_corners", "cast_as_built", "render_as_built", "EDGE", "PLATE", "FIXTURE", "NONE"]

# labels of the returns (internal): face k -> k, the edge zone of ridge k -> EDGE + k
EDGE = 1000
PLATE = -2
FIXTURE = -3
NONE = -1


def true_corners(gauge, Ts_G_F) -> np.ndarray:
    """Where the sharp ridges of ``gauge`` pierce the laser plane, in F.

    Parameters
    ----------
    gauge : Gauge
        Pass ``as_built.gauge`` for the truth of a realistic profile.
    Ts_G_F : array_like, shape (K, 4, 4) or (4, 4)
        Sensor poses in G, mm.

    Returns
    -------
    corners_F : ndarray, shape (K, n, 2) (or (n, 2))
        (x, z) in F, mm, in ridge order (not scan order).
    """
    Ts = np.asarray(Ts_G_F, dtype=np.float64)
    single = Ts.ndim == 2
    Ts = Ts.reshape(-1, 4, 4)
    R = Ts[:, :3, :3]
    t = Ts[:, :3, 3]
    ny = R[:, :, 1]
    off = np.sum(ny * t, axis=1)
    lam = (off[:, None] - (gauge.ridge_q @ ny.T).T) / (gauge.ridge_s @ ny.T).T
    P = gauge.ridge_q[None] + lam[..., None] * gauge.ridge_s[None]
    p_F = np.einsum("kji,kmj->kmi", R, P - t[:, None, :])
    out = p_F[..., [0, 2]]
    return out[0] if single else out


# --------------------------------------------------------------------------- ray casting


@njit(cache=True, nogil=True)
def _cyl_roots(ox, oy, oz, dx, dy, dz, a, u, r):
    """Ray parameters where the ray meets the cylinder (axis a + μ u, unit u, radius r)."""
    wx = ox - a[0]
    wy = oy - a[1]
    wz = oz - a[2]
    wu = wx * u[0] + wy * u[1] + wz * u[2]
    du = dx * u[0] + dy * u[1] + dz * u[2]
    wpx = wx - wu * u[0]
    wpy = wy - wu * u[1]
    wpz = wz - wu * u[2]
    dpx = dx - du * u[0]
    dpy = dy - du * u[1]
    dpz = dz - du * u[2]
    A = dpx * dpx + dpy * dpy + dpz * dpz
    B = 2.0 * (wpx * dpx + wpy * dpy + wpz * dpz)
    C = wpx * wpx + wpy * wpy + wpz * wpz - r * r
    disc = B * B - 4.0 * A * C
    if A <= 0.0 or disc < 0.0:
        return False, 0.0, 0.0
    sq = np.sqrt(disc)
    return True, (-B - sq) / (2.0 * A), (-B + sq) / (2.0 * A)


@njit(cache=True, nogil=True)
def _in_sector(px, py, pz, a, u, na, nb, sgn):
    """Whether p - a (across the axis u) lies between sgn·na and sgn·nb."""
    vx = px - a[0]
    vy = py - a[1]
    vz = pz - a[2]
    vu = vx * u[0] + vy * u[1] + vz * u[2]
    vx -= vu * u[0]
    vy -= vu * u[1]
    vz -= vu * u[2]
    c = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]
    pa = sgn * (na[0] * vx + na[1] * vy + na[2] * vz)
    pb = sgn * (nb[0] * vx + nb[1] * vy + nb[2] * vz)
    det = 1.0 - c * c
    alpha = (pa - c * pb) / det
    beta = (pb - c * pa) / det
    return alpha >= 0.0 and beta >= 0.0


@njit(cache=True, nogil=True)
def _cast_kernel(normals, offsets, ridge_q, ridge_s, x_lo, x_hi, y_lo, y_hi, kind, size, convex, axis_q,
                 chamfer_plane, plate_z, fixture, Rs, ts, d_F, z_apex, z_near, z_far, out, label, cosinc):
    """First hit of each ray on the as-built scene: points (x, z) in F, label, cos(incidence)."""
    n_ridges = ridge_q.shape[0]
    u_ax = np.empty((n_ridges, 3))
    for k in range(n_ridges):
        ln = np.sqrt(ridge_s[k, 0] ** 2 + ridge_s[k, 1] ** 2 + ridge_s[k, 2] ** 2)
        for j in range(3):
            u_ax[k, j] = ridge_s[k, j] / ln
    has_plate = np.isfinite(plate_z)
    has_fix = np.isfinite(fixture[0])
    for kp in range(Rs.shape[0]):
        for i in range(d_F.shape[0]):
            dxF = d_F[i, 0]
            dzF = d_F[i, 2]
            ox, oy, oz, dx, dy, dz = ray_in_gauge(Rs[kp], ts[kp], z_apex, dxF, dzF)
            dn = np.sqrt(dx * dx + dy * dy + dz * dz)
            best, face = first_face_hit(normals, offsets, ridge_q, ridge_s, x_lo, x_hi, y_lo, y_hi, ox, oy, oz,
                                        dx, dy, dz)
            lab = NONE
            cz = 0.0
            if face >= 0:
                lab = face
                cz = -(normals[face, 0] * dx + normals[face, 1] * dy + normals[face, 2] * dz) / dn
                px = ox + best * dx
                py = oy + best * dy
                pz = oz + best * dz
                for k in range(max(face - 1, 0), min(face + 1, n_ridges)):
                    if kind[k] == 0:
                        continue
                    na = normals[k]
                    nb = normals[k + 1]
                    sg = 1.0 if convex[k] else -1.0
                    if kind[k] == 1:
                        if not _in_sector(px, py, pz, axis_q[k], u_ax[k], na, nb, sg):
                            continue
                        ok, l1, l2 = _cyl_roots(ox, oy, oz, dx, dy, dz, axis_q[k], u_ax[k], size[k])
                        if not ok:
                            if convex[k]:
                                best = np.inf       # grazes through the removed tip: no return
                            continue
                        lam = l1 if convex[k] else l2
                        if lam <= 0.0:
                            continue
                        best = lam
                        hx = ox + lam * dx - axis_q[k, 0]
                        hy = oy + lam * dy - axis_q[k, 1]
                        hz = oz + lam * dz - axis_q[k, 2]
                        hu = hx * u_ax[k, 0] + hy * u_ax[k, 1] + hz * u_ax[k, 2]
                        hx -= hu * u_ax[k, 0]
                        hy -= hu * u_ax[k, 1]
                        hz -= hu * u_ax[k, 2]
                        hn = np.sqrt(hx * hx + hy * hy + hz * hz)
                        cz = abs(hx * dx + hy * dy + hz * dz) / (hn * dn)
                    else:
                        pc = chamfer_plane[k]
                        side = pc[0] * px + pc[1] * py + pc[2] * pz - pc[3]
                        if (convex[k] and side <= 0.0) or (not convex[k] and side >= 0.0):
                            continue
                        den = pc[0] * dx + pc[1] * dy + pc[2] * dz
                        if den >= 0.0:
                            best = np.inf
                            continue
                        lam = (pc[3] - (pc[0] * ox + pc[1] * oy + pc[2] * oz)) / den
                        if lam <= 0.0:
                            continue
                        best = lam
                        cz = -den / dn
                    lab = EDGE + k
                    break
            if has_plate and dz < 0.0:
                lam = (plate_z - oz) / dz
                if lam > 0.0 and lam < best:
                    px = ox + lam * dx
                    py = oy + lam * dy
                    if not (x_lo <= px <= x_hi and y_lo <= py <= y_hi):
                        best = lam
                        lab = PLATE
                        cz = -dz / dn
            if has_fix:
                if dz < 0.0:
                    lam = (fixture[2] - oz) / dz
                    if lam > 0.0 and lam < best:
                        px = ox + lam * dx
                        if fixture[0] <= px <= fixture[1]:
                            best = lam
                            lab = FIXTURE
                            cz = -dz / dn
                xw = fixture[0] if fixture[3] > 0 else fixture[1]
                if dx * fixture[3] > 0.0:
                    lam = (xw - ox) / dx
                    if lam > 0.0 and lam < best:
                        pz = oz + lam * dz
                        if plate_z <= pz <= fixture[2]:
                            best = lam
                            lab = FIXTURE
                            cz = abs(dx) / dn
            z = z_apex + best * dzF
            if best < np.inf and z >= z_near and z <= z_far:
                out[kp, i, 0] = best * dxF
                out[kp, i, 1] = z
                label[kp, i] = lab
                cosinc[kp, i] = cz
            else:
                out[kp, i, 0] = np.nan
                out[kp, i, 1] = np.nan
                label[kp, i] = NONE
                cosinc[kp, i] = 0.0


def cast_as_built(scene, Ts_G_F: np.ndarray, model):
    """Noise-free returns of the as-built scene.

    Parameters
    ----------
    scene : AsBuiltGauge
    Ts_G_F : ndarray, shape (K, 4, 4)
    model : ProfilerModel

    Returns
    -------
    points : ndarray, shape (K, n_points, 2)
        (x, z) in F, mm; NaN = no return.
    label : ndarray of int, shape (K, n_points)
        Face k: k; edge zone of ridge k: 1000 + k; plate -2; fixture -3; none -1.
    cos_incidence : ndarray, shape (K, n_points)
        Cosine of the angle between the ray and the surface normal.
    """
    K = Ts_G_F.shape[0]
    out = np.empty((K, model.n_points, 2))
    label = np.empty((K, model.n_points), dtype=np.int64)
    cosinc = np.empty((K, model.n_points))
    g = scene.gauge
    _cast_kernel(g.normals, g.offsets, g.ridge_q, g.ridge_s, g.x_range[0], g.x_range[1], g.y_range[0],
                 g.y_range[1], scene.edge_kind, scene.edge_size, scene.convex, scene.axis_q,
                 scene.chamfer_plane, scene.plate_z, scene.fixture,
                 np.ascontiguousarray(Ts_G_F[:, :3, :3]), np.ascontiguousarray(Ts_G_F[:, :3, 3]),
                 model.ray_directions(), model.z_apex, model.z_near, model.z_far, out, label, cosinc)
    return out, label, cosinc


# --------------------------------------------------------------------------- sensor effects


def _multipath(out, label, scene, Ts, rng):
    """Ghost clusters beside the concave ridges (in place)."""
    rm = scene.realism
    K = out.shape[0]
    n = scene.gauge.n_corners
    hit = rng.random((K, n)) < rm.multipath_rate
    toward_next = rng.random((K, n)) < 0.5
    start = rng.uniform(0.0, 0.3, (K, n))
    length = rng.uniform(*rm.multipath_length_mm, (K, n))
    depth = rng.uniform(*rm.multipath_depth_mm, (K, n))
    if rm.multipath_rate <= 0:
        return
    xc = true_corners(scene.gauge, Ts)[..., 0]                  # (K, n)
    # Scan direction of the faces: towards ridge k + 1.
    step = np.sign(np.diff(xc, axis=1))
    step = np.concatenate([step, step[:, -1:]], axis=1)
    x = out[..., 0]
    for k in np.flatnonzero(~scene.convex):
        sgn = np.where(toward_next[:, k], step[:, k], -step[:, k])[:, None]
        face = np.where(toward_next[:, k], k + 1, k)[:, None]
        dist = sgn * (x - xc[:, k:k + 1])
        on = (label == face) | (label == EDGE + k)
        sel = on & hit[:, k:k + 1] & (dist >= start[:, k:k + 1]) & (dist <= start[:, k:k + 1] + length[:, k:k + 1])
        frac = (dist - start[:, k:k + 1]) / length[:, k:k + 1]
        out[..., 1] += np.where(sel, depth[:, k:k + 1] * (1.0 - 0.5 * frac), 0.0)


def _steep_dropouts(out, cosinc, rm, rng):
    """Runs of missing returns where the laser meets the surface at a steep angle (in place)."""
    K, N = cosinc.shape
    u = rng.random((K, N))
    runs = rng.integers(1, 2 * rm.dropout_run_points, (K, N))
    if rm.steep_dropout_max <= 0:
        return
    theta = np.degrees(np.arccos(np.clip(cosinc, 0.0, 1.0)))
    lo, hi = rm.steep_dropout_deg
    p = rm.steep_dropout_max * np.clip((theta - lo) / (hi - lo), 0.0, 1.0) / rm.dropout_run_points
    idx = np.arange(N)
    ends = np.where(u < p, idx + runs, -1)
    dropped = np.maximum.accumulate(ends, axis=1) > idx
    out[dropped] = np.nan


def render_as_built(scene, Ts_G_F: np.ndarray, model, rng) -> np.ndarray:
    """Noise-free profiles of the as-built scene with multipath, scale error and steep dropouts.

    The sensor noise of :class:`~posekit.profiler.sensor.NoiseModel` is added by the caller.

    Parameters
    ----------
    scene : AsBuiltGauge
    Ts_G_F : ndarray, shape (K, 4, 4)
    model : ProfilerModel
    rng : numpy.random.Generator

    Returns
    -------
    profiles : ndarray, shape (K, n_points, 2)
        (x, z) in F, mm; NaN = no return.
    """
    out, label, cosinc = cast_as_built(scene, Ts_G_F, model)
    rm = scene.realism
    _multipath(out, label, scene, Ts_G_F, rng)
    out[..., 0] *= 1.0 + rm.scale_x_ppm * 1e-6
    out[..., 1] = model.z_mid + (out[..., 1] - model.z_mid) * (1.0 + rm.scale_z_ppm * 1e-6)
    _steep_dropouts(out, cosinc, rm, rng)
    return out
