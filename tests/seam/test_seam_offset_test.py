"""Issue 26 (deliverable 4): the integrity monitor's offset test — the estimate's offset from the kinematic pose,
averaged over the long window, against what the profile's training episodes showed
(posekit.seam.engine.integrity, posekit.seam.frontend.tune_offset).

The series here are written in the test (episodes whose offset has its own level plus an AR(1) wander), not by
posekit's simulator; the cell-level effect (an encoder offset after the profile was fitted) is in
tests/seam/test_seam_independent_cell.py.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.seam.engine.integrity import IntegrityMonitor
from posekit.seam.engine.offset_test import kinematic_offset, offset_limits, offset_means
from posekit.seam.frontend.tune_offset import calibrate_offset

WINDOW, LONG = 10, 120


def _pose(rng):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(0.0, 1.0, 3)).as_matrix()
    T[:3, 3] = rng.normal(0.0, 500.0, 3)
    return T


def test_kinematic_offset_is_the_relative_pose_in_the_kinematic_frame():
    rng = np.random.default_rng(0)
    kin = np.array([_pose(rng) for _ in range(20)])
    d = rng.normal(0.0, [0.5, 0.5, 0.5, 0.01, 0.01, 0.01], (20, 6))
    est = kin.copy()
    for i in range(20):                 # the estimate: the kinematic pose moved by d in its own frame
        est[i, :3, 3] = kin[i, :3, 3] + kin[i, :3, :3] @ d[i, :3]
        est[i, :3, :3] = kin[i, :3, :3] @ Rotation.from_rotvec(d[i, 3:]).as_matrix()
    np.testing.assert_allclose(kinematic_offset(est, kin), d, atol=1e-9)
    # one pose at a time (the filter's step: the compiled kernel) gives the same
    np.testing.assert_allclose([kinematic_offset(e, k) for e, k in zip(est, kin)], d, atol=1e-9)
    assert np.isnan(kinematic_offset(np.full((4, 4), np.nan), kin[0])).all()
    est[3, 0, 0] = np.nan
    out = kinematic_offset(est, kin)
    assert np.isnan(out[3]).all() and np.isfinite(np.delete(out, 3, axis=0)).all()


def test_offset_means_is_the_mean_of_the_last_window_counted_steps():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(300, 6))
    X[rng.random(300) < 0.2, 2] = np.nan              # a step without an offset is not counted
    ref = np.full(X.shape, np.nan)
    for t in range(300):
        seg = X[max(0, t - LONG + 1):t + 1]
        seg = seg[np.isfinite(seg).all(axis=1)]
        if len(seg) > WINDOW:
            ref[t] = seg.mean(axis=0)
    np.testing.assert_allclose(offset_means(X, LONG, WINDOW), ref, rtol=1e-9, atol=1e-12, equal_nan=True)


def _episodes(rng, n, steps=400, between=0.3, phi=0.97, level=(0.0, 0.0, -0.7, 0.0, 1e-3, 0.0)):
    """Offsets (mm, rad) of ``n`` episodes: a level per episode (``between`` of the wander's std) and an AR(1)
    wander of unit std (mm; 1e-3 rad for the rotations)."""
    unit = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3])
    out = []
    for _ in range(n):
        e = np.empty((steps, 6))
        e[0] = rng.normal(size=6)
        for t in range(1, steps):
            e[t] = phi * e[t - 1] + math.sqrt(1.0 - phi * phi) * rng.normal(size=6)
        out.append((np.asarray(level) + (between * rng.normal(size=6) + e) * unit) * 0.1)
    return out


def _flags(mon_args, X):
    mon = IntegrityMonitor(500, WINDOW, 1e-3, 1e-5, 0.0, 0, 0.0, LONG, **mon_args)
    return np.array([mon.update(0.0, 0, 0.0, 0.0, 500.0, offset=x).status != "tracking" for x in X])


def test_the_monitor_flags_exactly_where_the_statistic_leaves_its_bound():
    rng = np.random.default_rng(2)
    train = _episodes(rng, 6)
    mean, sd, samples, n = calibrate_offset([offset_means(x, LONG, WINDOW) for x in train])
    X = _episodes(rng, 1)[0]
    X[200:, 2] += 2.0 * (offset_limits(samples, 1e-3) * sd)[2]           # a change along z mid-way
    z = np.abs(offset_means(X, LONG, WINDOW) - mean) / sd / offset_limits(samples, 1e-3)
    expected = np.nan_to_num(z, nan=0.0).max(axis=1) > 1.0
    got = _flags({"offset_mean": mean, "offset_sd": sd, "offset_samples": samples}, X)
    assert expected.sum() > 20 and not expected[:WINDOW + 1].any()
    np.testing.assert_array_equal(got, expected)


def test_calibrated_on_a_few_episodes_it_rarely_flags_a_new_one_and_flags_a_large_change():
    rng = np.random.default_rng(3)
    train = _episodes(rng, 6)
    mean, sd, samples, n = calibrate_offset([offset_means(x, LONG, WINDOW) for x in train])
    assert n == 6 * (400 - WINDOW)
    # the episodes' levels differ (between 0.3 of the wander): the spread rests on few independent windows
    assert np.all(samples > 2.0) and np.all(samples < 40.0)
    args = {"offset_mean": mean, "offset_sd": sd, "offset_samples": samples}
    fresh = _episodes(rng, 30)
    alarms = np.mean([_flags(args, x).mean() for x in fresh])
    assert alarms < 0.01                                    # measured 0.0
    limit = offset_limits(samples, 1e-3) * sd
    shifted = [x + np.array([0.0, 0.0, 2.0 * limit[2], 0.0, 0.0, 0.0]) for x in fresh[:5]]
    caught = [_flags(args, x)[3 * WINDOW:].mean() for x in shifted]
    assert min(caught) > 0.9                                # a change twice the smallest flagged one: caught


def test_episodes_that_differ_leave_fewer_samples_and_a_wider_limit():
    rng = np.random.default_rng(4)
    alike = calibrate_offset([offset_means(x, LONG, WINDOW) for x in _episodes(rng, 4, between=0.0)])
    unlike = calibrate_offset([offset_means(x, LONG, WINDOW) for x in _episodes(rng, 4, between=3.0)])
    assert np.all(unlike[2] < 6.0)                          # about one value per episode
    assert np.all(alike[2] > unlike[2])
    assert np.all(offset_limits(unlike[2], 1e-3) > offset_limits(alike[2], 1e-3))


def test_without_a_calibration_or_a_long_window_there_is_no_offset_test():
    X = np.full((50, 6), 5.0)
    assert not _flags({}, X).any()
    mon = IntegrityMonitor(500, WINDOW, 1e-3, 1e-5, 0.0, 0, 0.0, 0, offset_mean=np.zeros(6),
                           offset_sd=np.ones(6), offset_samples=np.full(6, 10.0))
    assert not mon.tests_offset
    assert offset_limits([1.0, 2.0, 10.0, 0.0, 50.0, 3.0], 1e-3)[[0, 3]].tolist() == [math.inf, math.inf]


def test_the_reason_names_the_axis_the_offset_and_the_profile_s():
    mon = IntegrityMonitor(500, WINDOW, 1e-3, 1e-5, 0.0, 0, 0.0, LONG, offset_mean=np.array([0, 0, -0.7, 0, 0, 0]),
                           offset_sd=np.array([0.1, 0.1, 0.1, 1e-3, 1e-3, 1e-3]), offset_samples=np.full(6, 30.0))
    for _ in range(WINDOW + 1):
        rep = mon.update(0.0, 0, 0.0, 0.0, 500.0, offset=np.array([0, 0, -0.2, 0, math.radians(0.01), 0]))
    assert rep.status == "degraded"
    assert rep.reason.startswith("the estimate's offset from the kinematic pose along z over the last 11 steps "
                                 "-0.2 mm, the profile's episodes -0.7 ± 0.1 mm (beyond ")
    assert rep.reason.endswith("the kinematics err otherwise than when the profile was fitted (an encoder offset? "
                               "a tool or mount that moved?)")


def _runs(rng, n, steps=300):
    """Filter runs (tune_filter.FilterRun) whose estimate sits at the offsets of :func:`_episodes` from the
    kinematic pose."""
    from posekit.seam.frontend.tune_filter import FilterRun

    out = []
    for X in _episodes(rng, n, steps=steps):
        kin = np.array([_pose(rng) for _ in range(steps)])
        est = kin.copy()
        for i in range(steps):
            est[i, :3, 3] = kin[i, :3, 3] + kin[i, :3, :3] @ X[i, :3]
            est[i, :3, :3] = kin[i, :3, :3] @ Rotation.from_rotvec(X[i, 3:]).as_matrix()
        status = ["tracking"] * steps
        status[50] = "lost"                                    # left out of the calibration
        out.append((X, FilterRun(est, kin, np.ones((steps, 6)), status, np.zeros((steps, 0)), np.zeros((steps, 0)),
                                 kin)))
    return out


def test_tune_calibrates_the_offset_test_on_the_runs_and_says_what_it_flags():
    from types import SimpleNamespace

    from posekit.seam.frontend.tune_offset import fit_offset

    logs = [SimpleNamespace(config=SimpleNamespace(filter=SimpleNamespace(
        integrity_window_long=LONG, integrity_window=WINDOW, integrity_alpha_degraded=1e-3)))]
    said, put = [], []
    data = {"offset": "stale"}
    rng = np.random.default_rng(5)
    one = _runs(rng, 1)
    fit_offset(logs, [r for _, r in one], data, lambda *a: put.append(a), said.append)
    assert "offset" not in data and not put
    assert said == ["no offset test: 289 tested steps from 1 episode(s) (at least 100 from 2 episodes needed)"]
    said.clear()
    two = _runs(rng, 3)
    fit_offset(logs, [r for _, r in two], data, lambda *a: put.append(a), said.append)
    stat = [offset_means(X, LONG, WINDOW) for X, _ in two]
    for M in stat:
        M[50] = np.nan
    mean, sd, samples, n = calibrate_offset(stat)
    assert data["offset"]["mean"]["z_mm"] == {"value": pytest.approx(mean[2], abs=1e-9)}
    assert data["offset"]["sd"]["ry_deg"] == {"value": pytest.approx(math.degrees(sd[4]), rel=1e-7)}
    assert data["offset"]["samples"]["rx"] == round(float(samples[3]), 3)
    assert [p[0] for p in put] == [f"offset.{w}.{k}" for k in ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")
                                   for w in ("mean", "sd")]
    assert said[0].startswith("the offset test over 120 steps flags a change of the kinematics' offset of at least: x ")
    # and what 6 and 9 such episodes would flag: the same spread on twice and three times the samples
    limit6 = offset_limits(samples * 2.0, 1e-3) * sd
    assert said[1].startswith("with more episodes like these it would flag about (projected: the same spread, its "
                              f"samples in proportion): 6 episodes: x {limit6[0]:.2g} mm, y {limit6[1]:.2g} mm, ")
    assert f"; 9 episodes: x {(offset_limits(samples * 3.0, 1e-3) * sd)[0]:.2g} mm, " in said[1]
    assert len(said) == 2


def test_the_projection_from_three_episodes_comes_near_what_nine_give():
    """The checked-in profiles of the independent cell (the generator in the tests, not posekit's simulator), fitted
    on its episodes 0-2 and 0-8: three episodes projected to nine come within a factor 2.5 of the nine's own limit on
    every axis, where the three's own limit is up to 19 times it."""
    from posekit.seam.frontend.profile import load_profile
    from posekit.seam.frontend.tune_offset import projected_limits

    data = Path(__file__).parent / "data"
    three, nine = (load_profile(data / name).to_model() for name in ("independent_cell_profile.yaml",
                                                                     "independent_cell_profile_9.yaml"))
    lim3 = offset_limits(three.offset_samples, 1e-3) * three.offset_sd
    proj = projected_limits(three.offset_sd, three.offset_samples, 3, 9, 1e-3)
    lim9 = offset_limits(nine.offset_samples, 1e-3) * nine.offset_sd
    ratio = proj / lim9
    assert np.all((ratio > 1 / 2.5) & (ratio < 2.5)), ratio
    assert np.max(lim3 / lim9) > 15.0
    np.testing.assert_allclose(projected_limits(three.offset_sd, three.offset_samples, 3, 3, 1e-3), lim3, rtol=1e-12)


def test_episodes_whose_offset_does_not_wander_leave_a_finite_count():
    eps = [np.tile(np.array([0.1 * k, 0.0, -0.7 + 0.05 * k, 0.0, 1e-4 * k, 0.0]), (200, 1)) for k in range(3)]
    mean, sd, samples, n = calibrate_offset([offset_means(x, LONG, WINDOW) for x in eps])
    assert n == 3 * (200 - WINDOW)
    # all of the spread is between the episodes: one value each; an axis that never moves has none (no test)
    np.testing.assert_allclose(samples, [3.0, 0.0, 3.0, 0.0, 3.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(mean[[0, 2]], [0.1, -0.65], atol=1e-12)
