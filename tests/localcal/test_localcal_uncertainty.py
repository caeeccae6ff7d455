"""Honesty of ``std_rot_deg``/``std_t_mm``: Monte Carlo, autocorrelation theory and coverage on the verdict cases.

Print the coverage (true error within 3 sigma, every component) of the plain Gauss-Newton
covariance and of the time-correlation-corrected one that ``match`` reports, over many seeds::

    python -m tests.localcal.test_localcal_uncertainty 0 1 2 3 4 5 6 7 8 9
"""

import sys

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from posekit._autocorr import autocorrelation_time
from posekit.localcal.registration.alignment import umeyama
from posekit.localcal.registration.uncertainty import path_tangents, registration_covariance
from tests.localcal.test_localcal_verdict import good_cases, run_case


def test_autocorrelation_time_of_ar1_matches_theory():
    rng = np.random.default_rng(0)
    for phi in (0.0, 0.8, 0.95):
        w = rng.normal(size=200_000)
        x = lfilter([1.0], [1.0, -phi], w)[:, None]         # x[k] = phi x[k-1] + w[k]
        assert autocorrelation_time(x) == pytest.approx((1 + phi) / (1 - phi), rel=0.1, abs=0.1)


def test_gauss_newton_covariance_matches_monte_carlo():
    """White noise: the predicted std of rotation and translation equals the spread of 400 refits."""
    rng = np.random.default_rng(1)
    p = rng.normal(0, [300, 150, 40], (300, 3)) + [800.0, -200.0, 400.0]
    R = Rotation.random(random_state=rng).as_matrix()
    t = np.array([50.0, -30.0, 900.0])
    sigma = 2.0
    errs, stds = [], []
    for _ in range(400):
        q = p @ R.T + t + rng.normal(0, sigma, p.shape)
        Re, te, _ = umeyama(p, q)
        errs.append(np.r_[Rotation.from_matrix(Re @ R.T).as_rotvec(), te - t])
        cov, tau = registration_covariance(p, q, Re, te, correlated=False)
        stds.append(np.sqrt(np.diag(cov)))
    np.testing.assert_allclose(np.std(errs, axis=0), np.mean(stds, axis=0), rtol=0.12)


def test_point_to_line_covariance_drops_the_along_path_direction():
    """Pairs along a straight segment carry no information along it: projecting removes it."""
    t = np.linspace(0, 1, 200)
    p = np.c_[400 * t, 100 * np.sin(6 * t), 30 * np.cos(9 * t)]
    tg = path_tangents(p)
    np.testing.assert_allclose(np.linalg.norm(tg, axis=1), 1.0, atol=1e-12)
    q = p + np.random.default_rng(2).normal(0, 1.0, p.shape)
    full, _ = registration_covariance(p, q, np.eye(3), np.zeros(3), correlated=False)
    across, _ = registration_covariance(p, q, np.eye(3), np.zeros(3), tangents=tg, correlated=False)
    assert np.all(np.diag(across) > np.diag(full))           # less information without the along part


def coverage(seeds, k=3.0):
    """Share of the cases (with truth) whose 6 errors lie within k sigma: (reported, plain GN, n)."""
    hit_rep, hit_plain, n, rows = 0, 0, 0, []
    for seed in seeds:
        for name, src, dst, kw, T in good_cases(seed):
            if T is None:
                continue
            status, reg = run_case(src, dst, kw)
            if status == "error":
                continue
            err = np.r_[np.rad2deg(Rotation.from_matrix(reg.R @ T[:3, :3].T).as_rotvec()), reg.t_mm - T[:3, 3]]
            rep = np.r_[reg.std_rot_deg, reg.std_t_mm]
            inl = reg.inliers
            i_s, i_d = reg.pairs[inl, 0], reg.pairs[inl, 1]
            pd, tg = dst.positions[i_d], None
            if reg.mode != "timestamps":
                tga, sm = path_tangents(dst.positions, smoothed=True)
                pd, tg = sm[i_d], tga[i_d]
            cov, tau = registration_covariance(src.positions[i_s], pd, reg.R, reg.t_mm, reg.scale,
                                               tangents=tg, correlated=False)
            sd = np.sqrt(np.diag(cov))
            plain = np.r_[np.rad2deg(sd[:3]), sd[3:]]
            z_rep, z_plain = np.abs(err / rep).max(), np.abs(err / plain).max()
            hit_rep += z_rep <= k
            hit_plain += z_plain <= k
            n += 1
            rows.append((seed, name, z_rep, z_plain, np.abs(err / rep)))
    return hit_rep / n, hit_plain / n, n, rows


def test_reported_std_covers_the_true_error():
    rep, plain, n, rows = coverage([0])
    assert n >= 14
    assert rep >= 0.9, [r for r in rows if r[2] > 3]
    # the correlated-noise case needs the correction: the plain covariance misses it
    z = {r[1]: r for r in rows}
    assert z["smooth AR(1) camera noise ts"][3] > z["smooth AR(1) camera noise ts"][2]


if __name__ == "__main__":
    seeds = [int(a) for a in sys.argv[1:]] or [0]
    rep, plain, n, rows = coverage(seeds)
    for seed, name, zr, zp, _ in rows:
        if zr > 3 or zp > 3:
            print(f"seed {seed} {name:40s} max|err|/std reported {zr:5.2f} plain GN {zp:5.2f}")
    print(f"{n} good cases with truth, seeds {seeds}: all 6 errors within 3 sigma: reported (GN x autocorrelation "
          f"time) {rep:.1%}, plain Gauss-Newton {plain:.1%}")
    z = np.array([r[4] for r in rows])
    print("per component (rot x y z, t x y z) within 2 sigma: " + " ".join(f"{v:.0%}" for v in (z <= 2).mean(0))
          + "; within 3 sigma: " + " ".join(f"{v:.0%}" for v in (z <= 3).mean(0)))
