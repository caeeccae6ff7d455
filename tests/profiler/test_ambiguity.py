"""Ambiguous gauges: refused at load and by the design rules unless the mounting is given.

A gauge whose cross-section is symmetric under a 180° turn about the vertical gives the
same profile at two poses (the corners read in reverse order fit the turned pose), so the
estimator cannot choose between them on its own.
"""

from dataclasses import replace

import numpy as np
import pytest

from posekit.errors import EstimationError, GaugeError, one_line
from posekit.profiler import (
    BUNDLED_GAUGES,
    NoiseModel,
    bundled_gauge,
    detect_corners,
    gauge_from_design,
    load_gauge,
    render_profiles,
    sample_poses,
    solve_pose,
)
from posekit.profiler.estimate.pipeline import estimate_batch
from posekit.profiler.gauge.ambiguity import AMBIGUITY_MIN_MISS_UM, gauge_ambiguity
from posekit.profiler.gauge.design import random_gauge
from posekit.profiler.gauge.model import gauge_to_yaml
from posekit.profiler.studies.evaluate import pose_errors

SYMMETRIC = ("its cross-section is symmetric under a 180° turn about the vertical: read in reverse order, the "
             "corners fit the ridges exactly at another pose")
GIVE_MOUNTING = "; give the mounting (--mounting normal|reversed)"


def symmetric_gauge(dx_mm=0.0, **kw):
    """5 ridges, the cross-section and the ridges symmetric under a 180° turn about z.

    Under the turn (x, y) -> (-x, -y) face j (z = a x + b y + c) becomes face 5 - j and
    ridge k (x = x_k + u_k y) ridge 4 - k: a_{5-j} = -a_j, b_{5-j} = -b_j, x_{4-k} = -x_k,
    u_{4-k} = u_k; the y-slopes follow from the u's (``b2 = -u2 a2`` makes the middle
    ridge symmetric). ``dx_mm`` moves ridge 0 to break the symmetry by a little.
    """
    a = [0.5, -0.45, 0.4, -0.4, 0.45, -0.5]
    x = [-45.0 + dx_mm, -25.0, 0.0, 25.0, 45.0]
    u = [0.25, -0.1, 0.15, -0.1, 0.25]
    b2 = -u[2] * a[2]
    b1 = b2 - u[1] * (a[1] - a[2])
    b0 = b1 - u[0] * (a[0] - a[1])
    return gauge_from_design("sym-5", x, a, u, y_slope0=b0, extent=((-60, 60), (-20, 20)), **kw)


@pytest.mark.parametrize("name", BUNDLED_GAUGES)
def test_bundled_gauges_are_unambiguous(name):
    g = bundled_gauge(name)
    assert g.ambiguity is None
    assert gauge_ambiguity(g) is None


def test_symmetric_gauge_refused_at_load(tmp_path):
    g = symmetric_gauge(mounting="normal")
    assert g.ambiguity == SYMMETRIC
    path = tmp_path / "sym.yaml"
    path.write_text(gauge_to_yaml(g))
    with pytest.raises(GaugeError) as exc:
        load_gauge(path)
    assert str(exc.value) == one_line(f"{path}: gauge 'sym-5' is ambiguous: {SYMMETRIC}{GIVE_MOUNTING}")
    for mounting in ("normal", "reversed"):
        h = load_gauge(path, mounting=mounting)
        assert h.ambiguity == SYMMETRIC
        np.testing.assert_allclose(h.ridge_q, g.ridge_q, atol=1e-9)


def test_design_rule_check_reports_it():
    with pytest.raises(GaugeError) as exc:
        symmetric_gauge()
    assert str(exc.value) == f"design: gauge 'sym-5' is ambiguous: {SYMMETRIC}{GIVE_MOUNTING}"


def test_nearly_symmetric_gauge_is_too_shallow_to_tell():
    """Ridge 0 moved by 10 µm: the reversed reading still fits within ~2 µm, far below the noise's reach."""
    with pytest.raises(GaugeError, match=r"design: gauge 'sym-5' is ambiguous: read in reverse order, the corners "
                                         r"fit the ridges at another pose within 1\.\d\d µm RMS \(a usable gauge "
                                         r"misses by >= 10 µm\): too close to symmetric under a 180° turn; give "
                                         r"the mounting \(--mounting normal\|reversed\)$"):
        symmetric_gauge(dx_mm=0.01)
    # 100 µm off symmetric: the reversed reading misses by ~19 µm, enough for an exact drawing ...
    assert AMBIGUITY_MIN_MISS_UM == 10.0
    assert symmetric_gauge(dx_mm=0.1).ambiguity is None
    # ... but not for a gauge whose faces are only known to 5 µm: the limit is 5 x the tolerance
    with pytest.raises(GaugeError, match=r"within 1\d\.\d\d µm RMS \(a usable gauge misses by >= 25 µm\)"):
        symmetric_gauge(dx_mm=0.1, tolerance_um=5.0)


def test_the_ambiguity_is_real_and_the_mounting_resolves_it():
    """Both readings fit a symmetric gauge's profile; each mounting gives its own pose, 180° apart."""
    g = symmetric_gauge(mounting="normal")
    Ts = sample_poses(g, 10, rng=3)
    profiles = render_profiles(g, Ts, NoiseModel(), rng=3)
    turn = np.diag([-1.0, -1.0, 1.0])
    for T, prof in zip(Ts, profiles):
        corners = detect_corners(prof, 5)
        with pytest.raises(EstimationError, match=r"^gauge 'sym-5' is ambiguous \(its cross-section is symmetric "
                                                  r"under a 180° turn about the vertical: .*\); give the mounting "
                                                  r"\('normal' or 'reversed'\)$"):
            solve_pose(corners, g)
        normal = solve_pose(corners, g, mounting="normal", noise=NoiseModel())
        rev = solve_pose(corners, g, mounting="reversed", noise=NoiseModel())
        assert normal.status == rev.status == "ok"
        assert rev.chi2 == pytest.approx(normal.chi2, rel=1e-3, abs=1e-6)
        err = pose_errors(normal.T_G_F, T)
        assert np.all(np.abs(err) < 5 * np.sqrt(np.diag(normal.cov)))
        # the reversed reading is the pose turned 180° about the gauge's vertical axis of symmetry
        np.testing.assert_allclose(rev.T_G_F[:3, :3], turn @ normal.T_G_F[:3, :3], atol=1e-6)


def test_estimate_batch_with_mounting_on_a_symmetric_gauge():
    g = symmetric_gauge(mounting="normal")
    Ts = sample_poses(g, 6, rng=5)
    profiles = render_profiles(g, Ts, NoiseModel(), rng=5)
    records = [rec for rec, _ in estimate_batch(profiles, g, mounting="normal")]
    assert [r["status"] for r in records] == ["ok"] * 6
    err_um = np.abs(np.array([r["t_mm"] for r in records]) - Ts[:, :3, 3]) * 1e3
    assert np.all(err_um < 5 * np.array([r["std_t_um"] for r in records]))
    records = [rec for rec, _ in estimate_batch(profiles, g)]                  # mounting 'auto'
    assert [r["status"] for r in records] == ["error"] * 6
    assert records[0]["error"].startswith("gauge 'sym-5' is ambiguous (its cross-section is symmetric")


def test_runtime_guard_when_both_orders_fit():
    """A gauge that slipped past the load check: the record says the mounting cannot be told."""
    g = replace(symmetric_gauge(mounting="normal"), ambiguity=None)
    T = sample_poses(g, 1, rng=8)[0]
    corners = detect_corners(render_profiles(g, T, NoiseModel(), rng=8), 5)
    est = solve_pose(corners, g, noise=NoiseModel())
    assert est.status == "suspect"
    assert est.chi2 < 18.5
    assert est.reason.startswith(f"the {'normal' if est.reversed else 'reversed'} corner order fits too (chi2 = ")
    assert est.reason.endswith("): the mounting cannot be told from this profile, give it "
                               "(--mounting normal|reversed)")


@pytest.mark.parametrize("n", [4, 5, 7, 10])
def test_random_gauges_are_never_ambiguous(n):
    for seed in range(3):
        assert random_gauge(n, seed).ambiguity is None


def test_a_reading_from_below_the_gauge_does_not_count():
    """This gauge's cross-section is point-symmetric in the laser plane: the reversed reading fits exactly
    with the sensor under the gauge, looking up through the material. That pose is impossible, so the
    gauge is not ambiguous and 'auto' keeps the real pose."""
    from posekit.profiler.gauge.ambiguity import pose_is_possible

    g = gauge_from_design("steep", [-30, -10, 10, 30], [0.2, -0.2, 1.2, -0.2, 0.2], [0.1, -0.1, 0.1, -0.1],
                          extent=((-45, 45), (-20, 20)))
    assert g.ambiguity is None
    Ts = sample_poses(g, 20, rng=9)
    profiles = render_profiles(g, Ts, NoiseModel(), rng=9)
    for T, prof in zip(Ts, profiles):
        corners = detect_corners(prof, 4)
        est = solve_pose(corners, g, noise=NoiseModel())
        assert not est.reversed and est.status == "ok"
        assert np.all(np.abs(pose_errors(est.T_G_F, T)) < 5 * np.sqrt(np.diag(est.cov)))
        below = solve_pose(corners, g, mounting="reversed", noise=NoiseModel())
        assert below.T_G_F[2, 2] > 0.9                                   # F's z (line of sight) points up
        assert not pose_is_possible(g, below.T_G_F, corners.points[::-1])
        assert below.status == "suspect"
        assert ("at the fitted pose the sensor would see a face from behind (through the gauge): no real pose "
                "gives these corners") in below.reason
