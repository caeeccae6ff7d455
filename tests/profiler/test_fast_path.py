"""One estimation path: the real-time function equals the checked estimator, verdict included."""

import time

import numpy as np
import pytest
import yaml

from posekit.profiler import NoiseModel, bundled_gauge, render_profiles, sample_poses
from posekit.profiler.estimate.corner_params import CornerParams
from posekit.profiler.estimate.corners import gauge_turns
from posekit.profiler.estimate.fast import estimate_profile_unchecked, warm_gate
from posekit.profiler.estimate.pipeline import estimate_pose
from posekit.profiler.estimate.solve import METHODS
from posekit.profiler.gauge.model import MOUNTINGS, gauge_to_yaml, load_gauge
from posekit.profiler.stream.server import PoseServer
from posekit.profiler.stream.stream_client import SensorClient

PARAMS = CornerParams()


def _fast(points, gauge, method="mle", mounting="auto", **kw):
    return estimate_profile_unchecked(np.ascontiguousarray(points, dtype=np.float64), gauge, PARAMS,
                                      gauge_turns(gauge), METHODS.index(method), MOUNTINGS.index(mounting), **kw)


def _wrong_gauge_profiles(tmp_path, count=30, tolerance_um=2.0):
    """demo-5 profiles and a demo-5 file whose face 2 is 0.1 mm off the one the profiles saw."""
    gauge = bundled_gauge("demo-5")
    doc = yaml.safe_load(gauge_to_yaml(gauge))
    doc["planes"][2]["offset"] = float(gauge.offsets[2] + 0.1)
    doc["tolerance_um"] = tolerance_um
    path = tmp_path / "wrong.yaml"
    path.write_text(yaml.safe_dump(doc))
    Ts = sample_poses(gauge, count, rng=50)
    return render_profiles(gauge, Ts, NoiseModel(), rng=51), load_gauge(path)


def _same(res, est):
    assert res.status == est.status and res.reason == est.reason
    np.testing.assert_allclose(res.T_G_F, est.T_G_F, atol=1e-9)
    np.testing.assert_allclose(res.cov, est.cov, rtol=1e-7, atol=1e-18)
    np.testing.assert_allclose(res.chi2, est.chi2, rtol=1e-7, atol=1e-9)
    assert res.dof == est.dof and res.reversed == est.reversed
    assert res.reprojection_um == pytest.approx(est.reprojection_um, rel=1e-7, abs=1e-9)


@pytest.mark.parametrize("name", ["demo-4", "demo-5", "demo-7"])
@pytest.mark.parametrize("mounting", ["auto", "normal"])
def test_fast_path_equals_checked_path_on_good_data(name, mounting):
    gauge = bundled_gauge(name)
    Ts = sample_poses(gauge, 20, rng=21)
    profiles = render_profiles(gauge, Ts, NoiseModel(), rng=22)
    statuses = []
    for prof in profiles:
        corners, est = estimate_pose(prof, gauge, mounting=mounting)
        res = _fast(prof, gauge, mounting=mounting)
        _same(res, est)
        np.testing.assert_array_equal(res.corners.points, corners.points)
        statuses.append(res.status)
        # warm start from a nearby pose (a stream's previous frame): the same minimum, the same verdict
        warm = _fast(prof, gauge, mounting=mounting, T_init=est.T_G_F, rev_init=est.reversed,
                     gate=warm_gate(gauge.n_corners))
        assert warm.status == est.status and not warm.cold_restart
        np.testing.assert_allclose(warm.T_G_F, est.T_G_F, atol=1e-6)
        np.testing.assert_allclose(warm.chi2, est.chi2, rtol=1e-4, atol=1e-6)
    assert statuses.count("ok") >= 19                   # good data: (almost) all ok


def test_fast_path_equals_checked_path_on_a_wrong_gauge(tmp_path):
    """demo-5 profiles against a wrong file (with a tolerance): suspect with the same χ² and reason."""
    profiles, other = _wrong_gauge_profiles(tmp_path)
    seen = set()
    for prof in profiles:
        res = _fast(prof, other)
        try:
            _, est = estimate_pose(prof, other)
        except Exception as exc:                        # the detector refuses the profile
            assert res.status == "error" and res.error == str(exc) and res.T_G_F is None
            seen.add("error")
            continue
        _same(res, est)
        assert res.status == "suspect" and res.chi2 > 100 and res.dof == 4
        assert res.reason.startswith("chi2 = ")
        seen.add("suspect")
    assert "suspect" in seen


def test_fast_path_closed_form_and_failures():
    gauge = bundled_gauge("demo-5")
    prof = render_profiles(gauge, sample_poses(gauge, 1, rng=3), NoiseModel(), rng=4)[0]
    _, est = estimate_pose(prof, gauge, method="cf")
    _same(_fast(prof, gauge, method="cf"), est)
    cut = prof.copy()
    cut[: len(cut) // 2] = np.nan
    res = _fast(cut, gauge)
    assert res.status == "error" and res.error.startswith("expected 5 corners for gauge 'demo-5'")
    assert res.n_valid == np.isfinite(cut).all(axis=1).sum() and res.corners is None
    assert _fast(np.full((10, 2), np.nan), gauge).n_valid == 0


def test_server_record_is_suspect_on_a_wrong_gauge(tmp_path):
    """The server estimates demo-5 profiles with a wrong gauge file: the records say so."""
    profiles, other = _wrong_gauge_profiles(tmp_path)
    records = []

    class Sink:
        def put(self, rec):
            records.append(rec)

    server = PoseServer(other, record_sink=Sink(), queue_size=64)
    host, port = server.start()
    try:
        with SensorClient(host, port) as c:
            for k, prof in enumerate(profiles):
                c.send_profile(k, prof)
        t_end = time.monotonic() + 10.0
        while len(records) < len(profiles) and time.monotonic() < t_end:
            time.sleep(0.01)
    finally:
        server.stop()
    assert len(records) == len(profiles)
    suspect = [r for r in records if r["status"] == "suspect"]
    assert suspect and {r["status"] for r in records} <= {"suspect", "error"}
    for r in suspect:
        assert r["chi2"] > 100 and r["dof"] == 4 and r["reason"].startswith("chi2 = ")
        assert r["t_mm"] is not None and r["error"] is None
        # the offline estimate of the same (float32-transported) profile: the same verdict
        _, est = estimate_pose(profiles[r["seq"]].astype(np.float32).astype(np.float64), other)
        assert est.status == "suspect"
        np.testing.assert_allclose(r["chi2"], est.chi2, rtol=1e-4)
    st = server.stats()
    assert st["suspect"] == len(suspect) and st["ok"] == 0
    assert st["processed"] == st["ok"] + st["suspect"] + st["errors"]


@pytest.mark.parametrize("name", ["demo-5", "demo-7"])
def test_other_order_left_unsolved_only_when_it_cannot_matter(name, monkeypatch):
    """The solver skips the other corner order when the first is clearly best; the verdicts, χ² and
    poses equal those with both orders solved — good, 3x-noisy and reversed-mounting profiles."""
    from posekit.profiler.estimate import solve

    gauge = bundled_gauge(name)
    assert gauge.reversed_miss_um >= solve.SKIP_OTHER_ORDER_MISS_UM
    Ts = sample_poses(gauge, 15, rng=31)
    good = render_profiles(gauge, Ts, NoiseModel(), rng=32)
    noisy = render_profiles(gauge, Ts, NoiseModel(30, 15), rng=33)
    flipped = good[:, ::-1].copy()                                   # the sensor mounted the other way round
    calls = []
    real = solve._solve_order
    monkeypatch.setattr(solve, "_solve_order", lambda *a, **k: calls.append(a[5]) or real(*a, **k))
    results = []
    for skip in (True, False):
        if not skip:
            monkeypatch.setattr(solve, "SKIP_OTHER_ORDER_MISS_UM", np.inf)
        calls.clear()
        results.append([estimate_pose(p, gauge)[1] for p in np.concatenate([good, noisy, flipped])])
        if skip:
            assert calls.count(True) < len(calls) // 2               # most good profiles: one order solved
        else:
            assert len(calls) == 2 * 45
    for a, b in zip(*results):
        assert (a.status, a.reason, a.reversed, a.dof) == (b.status, b.reason, b.reversed, b.dof)
        np.testing.assert_array_equal(a.T_G_F, b.T_G_F)
        assert a.chi2 == b.chi2
    assert {e.reversed for e in results[0][30:]} == {True}
