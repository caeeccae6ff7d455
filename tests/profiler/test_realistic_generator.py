"""A second, simpler profile generator, independent of posekit's simulator, and its own checks.

posekit's simulator (:mod:`posekit.profiler.sim.realism`) casts the LJ-X8400's fan of rays at
a 3D as-built gauge with cylindrical fillets. This generator shares none of that code: it
cuts the gauge's planes with the laser plane analytically (a polyline in F's x–z plane),
samples it at a uniform x spacing (a different sampling than the fan's), and adds its own
defects in 2D — circular fillets and straight chamfers at the corners, a plate and a
fixture as horizontal lines beside the gauge, ghost clusters beside valleys, face offsets
(machining), scale error, dropout runs and Gaussian noise. The corner detector is measured
on both (tests/profiler/test_realistic_independent.py).
"""

from dataclasses import dataclass, replace

import numpy as np
import pytest

from posekit.profiler import bundled_gauge
from posekit.profiler.gauge.design import random_gauge

Z_CENTER_MM = 442.5          # the depth about which the scale error acts (LJ-X8400 mid-range)


@dataclass(frozen=True)
class Defects:
    """What the independent generator adds (all off by default)."""

    radius_mm: float = 0.0           # fillet radius at every corner (largest; each corner 0.3-1x)
    chamfer_mm: float = 0.0          # chamfer leg along each face at every other corner
    plate: bool = False              # plate 8 mm below the lowest corner, both sides
    fixture: bool = False            # a 10 mm flat 4 mm beside the gauge, near its edge's height
    multipath_mm: float = 0.0        # ghost depth beside every valley (0.4-1x this), 2 mm long
    offset_um: float = 0.0           # 1σ of each face's offset (the as-built gauge, per gauge)
    scale_ppm: float = 0.0           # x and z scale error (x: +, z: -)
    dropouts: int = 0                # runs of 3-15 missing points
    noise_x_um: float = 10.0
    noise_z_um: float = 5.0


ALL = Defects(radius_mm=0.8, chamfer_mm=0.5, plate=True, fixture=True, multipath_mm=0.5, offset_um=10.0,
              scale_ppm=100.0, dropouts=6)
ONE_EACH = {
    "rounded": Defects(radius_mm=1.0),
    "chamfer": Defects(chamfer_mm=0.7),
    "fixture": Defects(plate=True, fixture=True),
    "multipath": Defects(multipath_mm=0.6),
    "machining": Defects(offset_um=10.0),
    "scale": Defects(scale_ppm=100.0),
    "dropouts": Defects(dropouts=8),
    "all": ALL,
}


def random_pose(gauge, rng):
    """A pose T_G_F over the gauge: F's z down, x along G's x, mm; offsets drawn from rng."""
    q = gauge.ridge_q
    cx = 0.5 * (q[0, 0] + q[-1, 0])
    z0 = float(np.mean(q[:, 2])) + 440.0
    ax, ay, az = np.radians(rng.uniform(-1, 1, 3) * np.array([3.0, 3.0, 6.0]))
    cxa, sxa, cya, sya, cza, sza = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    Rx = np.array([[1, 0, 0], [0, cxa, -sxa], [0, sxa, cxa]])
    Ry = np.array([[cya, 0, sya], [0, 1, 0], [-sya, 0, cya]])
    Rz = np.array([[cza, -sza, 0], [sza, cza, 0], [0, 0, 1]])
    R0 = np.diag([1.0, -1.0, -1.0])
    R = R0 @ Rz @ Ry @ Rx
    T = np.eye(4)
    T[:3, :3] = R
    # rotate about the point 440 mm in front of the sensor, then shift
    pivot_G = np.array([cx, 0.0, z0 - 440.0])
    T[:3, 3] = pivot_G - R @ np.array([0.0, 0.0, 440.0]) + rng.uniform(-1, 1, 3) * np.array([5.0, 5.0, 20.0])
    return T


def section(normals, offsets, x_range, T_G_F):
    """The gauge's faces cut by the laser plane: lines ``a x + b z = c`` in F, corners, ends.

    Returns ``(lines (n+1, 3), vertices (n+2, 2))``: vertices are the outer end of face 0,
    the corners, the outer end of face n, in (x, z) of F, mm.
    """
    R = T_G_F[:3, :3]
    t = T_G_F[:3, 3]
    ab = normals @ R[:, [0, 2]]
    c = offsets - normals @ t
    lines = np.column_stack([ab, c])
    verts = []
    # outer end of face 0: G's x = x_range[0], i.e. R[0,0] x + R[0,2] z = x_lo - t_x
    edge = np.array([R[0, 0], R[0, 2], x_range[0] - t[0]])
    verts.append(np.linalg.solve(np.array([lines[0, :2], edge[:2]]), [lines[0, 2], edge[2]]))
    for k in range(len(lines) - 1):
        verts.append(np.linalg.solve(lines[k:k + 2, :2], lines[k:k + 2, 2]))
    edge = np.array([R[0, 0], R[0, 2], x_range[1] - t[0]])
    verts.append(np.linalg.solve(np.array([lines[-1, :2], edge[:2]]), [lines[-1, 2], edge[2]]))
    return lines, np.array(verts)


def _fillet(P, A, B, r):
    """Circle of radius r tangent to the faces P→A and P→B: centre and the tangent points."""
    u1 = (A - P) / np.linalg.norm(A - P)
    u2 = (B - P) / np.linalg.norm(B - P)
    alpha = np.arccos(np.clip(u1 @ u2, -1, 1))          # the angle between the two faces
    d = r / np.tan(alpha / 2)                            # tangent distance
    bis = (u1 + u2) / np.linalg.norm(u1 + u2)
    return P + bis * r / np.sin(alpha / 2), P + d * u1, P + d * u2


def _corner_patch(P, A, B, kind, size):
    """Replace the sharp corner P between points A (before) and B (after): polyline points."""
    if kind == "chamfer":
        u1 = (A - P) / np.linalg.norm(A - P)
        u2 = (B - P) / np.linalg.norm(B - P)
        return [P + size * u1, P + size * u2]
    C, T1, T2 = _fillet(P, A, B, size)
    a1 = np.arctan2(*(T1 - C)[::-1])
    a2 = np.arctan2(*(T2 - C)[::-1])
    da = (a2 - a1 + np.pi) % (2 * np.pi) - np.pi
    ang = a1 + da * np.linspace(0, 1, 25)
    return list(C + size * np.column_stack([np.cos(ang), np.sin(ang)]))


def _sample(poly, dx):
    """Points of a polyline (sorted by x) at a uniform x spacing."""
    poly = np.asarray(poly)
    x = np.arange(poly[0, 0], poly[-1, 0], dx)
    return np.column_stack([x, np.interp(x, poly[:, 0], poly[:, 1])])


def generate(gauge, T_G_F, defects: Defects, rng, dx=0.1):
    """One profile (N, 2) in F (NaN = no return, sorted by x) and its truth.

    Returns ``(profile, corners)``: the sharp corners of the (as-built, scaled) faces in
    scan order — what a perfect detector would report.
    """
    normals, offsets = gauge.normals, gauge.offsets
    lines, verts = section(normals, offsets, gauge.x_range, T_G_F)
    n = len(verts) - 2
    if verts[0, 0] > verts[-1, 0]:
        verts = verts[::-1]
    corners = verts[1:-1].copy()
    # 2D corner treatment
    poly = [verts[0]]
    for k in range(1, n + 1):
        P, A, B = verts[k], verts[k - 1], verts[k + 1]
        if defects.chamfer_mm > 0 and k % 2 == 0:
            poly += _corner_patch(P, A, B, "chamfer", defects.chamfer_mm)
        elif defects.radius_mm > 0:
            poly += _corner_patch(P, A, B, "fillet", defects.radius_mm * rng.uniform(0.3, 1.0))
        else:
            poly.append(P)
    poly.append(verts[-1])
    pts = _sample(poly, dx)
    # ghosts beside the valleys (z is depth: a valley is deeper than both neighbours)
    if defects.multipath_mm > 0:
        for k in range(1, n + 1):
            P = verts[k]
            if P[1] > verts[k - 1][1] and P[1] > verts[k + 1][1]:
                side = rng.choice([-1.0, 1.0])
                dist = side * (pts[:, 0] - P[0])
                on = (dist >= 0.1) & (dist <= 2.1)
                depth = defects.multipath_mm * rng.uniform(0.4, 1.0)
                pts[on, 1] += depth * (1 - 0.4 * (dist[on] - 0.1) / 2.0)
    parts = [pts]
    if defects.plate or defects.fixture:
        R, t = T_G_F[:3, :3], T_G_F[:3, 3]
        z_plate = float(np.min([p @ R[2, [0, 2]] + t[2] for p in verts])) - 8.0     # G height
        plate = np.array([R[2, 0], R[2, 2], z_plate - t[2]])                          # a x + b z = c
        lo, hi = verts[0, 0], verts[-1, 0]
        fix = (np.inf, -np.inf)
        if defects.fixture:                 # its top hides the plate under it
            right = rng.random() < 0.5
            end = verts[-1] if right else verts[0]
            x = end[0] + (1.0 if right else -1.0) * np.arange(4.0, 14.0, dx)
            parts.append(np.column_stack([x, np.full_like(x, end[1] + rng.uniform(-3, 3))]))
            fix = (x.min() - dx, x.max() + dx)
        if defects.plate:
            for xa, xb in ((lo - 60.0, lo - 3.0), (hi + 3.0, hi + 60.0)):
                x = np.arange(xa, xb, dx)
                x = x[(x < fix[0]) | (x > fix[1])]
                parts.append(np.column_stack([x, (plate[2] - plate[0] * x) / plate[1]]))
    prof = np.concatenate(parts)
    prof = prof[np.argsort(prof[:, 0])]
    if defects.scale_ppm:
        s = defects.scale_ppm * 1e-6
        prof[:, 0] *= 1 + s
        prof[:, 1] = Z_CENTER_MM + (prof[:, 1] - Z_CENTER_MM) * (1 - s)
        corners[:, 0] *= 1 + s
        corners[:, 1] = Z_CENTER_MM + (corners[:, 1] - Z_CENTER_MM) * (1 - s)
    prof[:, 0] += rng.normal(0, defects.noise_x_um * 1e-3, len(prof))
    prof[:, 1] += rng.normal(0, defects.noise_z_um * 1e-3, len(prof))
    for _ in range(defects.dropouts):
        i = rng.integers(0, len(prof))
        prof[i:i + rng.integers(3, 16)] = np.nan
    return prof, corners


def as_built(gauge, offset_um, rng):
    """The gauge with every face's offset off its drawing by N(0, offset_um) (per gauge)."""
    if offset_um == 0:
        return gauge
    return replace(gauge, offsets=gauge.offsets + rng.normal(0, offset_um * 1e-3, len(gauge.offsets)))


def measurement_gauges():
    """The gauges the independent measurements use: bundled and random ones."""
    return [bundled_gauge(n) for n in ("demo-4", "demo-5", "demo-7", "demo-10")] + \
        [random_gauge(n, 500 + n) for n in (4, 5, 7, 10)]


# --------------------------------------------------------------------------- the generator's own checks


def test_section_corners_agree_with_the_simulators_truth(gauge5):
    """Analytic corners here == where the simulator's ridges pierce the laser plane."""
    from posekit.profiler.sim.realism_render import true_corners

    rng = np.random.default_rng(1)
    for _ in range(5):
        T = random_pose(gauge5, rng)
        _, verts = section(gauge5.normals, gauge5.offsets, gauge5.x_range, T)
        np.testing.assert_allclose(verts[1:-1], true_corners(gauge5, T), atol=1e-9)


def test_sharp_profile_lies_on_the_faces(gauge5):
    rng = np.random.default_rng(2)
    T = random_pose(gauge5, rng)
    prof, corners = generate(gauge5, T, Defects(noise_x_um=0, noise_z_um=0), rng)
    lines, _ = section(gauge5.normals, gauge5.offsets, gauge5.x_range, T)
    d = np.abs(prof @ lines[:, :2].T - lines[:, 2]) / np.linalg.norm(lines[:, :2], axis=1)
    assert np.all(d.min(axis=1) < 1e-9)                  # every point on some face
    assert len(corners) == 5 and np.all(np.diff(corners[:, 0]) > 0)


@pytest.mark.parametrize("kind, size", [("fillet", 1.0), ("chamfer", 0.6)])
def test_corner_patches_touch_both_faces(kind, size):
    P, A, B = np.array([0.0, 0.0]), np.array([-5.0, 2.0]), np.array([5.0, 3.0])
    pts = np.array(_corner_patch(P, A, B, kind, size))
    for end, Q in ((pts[0], A), (pts[-1], B)):
        u = (Q - P) / np.linalg.norm(Q - P)
        assert abs(u[0] * (end - P)[1] - u[1] * (end - P)[0]) < 1e-9      # the ends lie on the faces
    if kind == "fillet":
        C, _, _ = _fillet(P, A, B, size)
        np.testing.assert_allclose(np.linalg.norm(pts - C, axis=1), size, atol=1e-9)
        # the arc cuts the corner: every point lies inside the angle, off the sharp corner
        assert np.all(np.linalg.norm(pts - P, axis=1) > 0.1 * size)
    else:
        assert np.linalg.norm(pts[1] - pts[0]) == pytest.approx(2 * size * np.sin(0.5 * np.arccos(
            ((A - P) @ (B - P)) / np.linalg.norm(A - P) / np.linalg.norm(B - P))))
