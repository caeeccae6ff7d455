"""Pose filters on streams of real estimates: a robot at rest, a step, a ramp, gaps, bad input."""

import json

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.geometry import rotation_vector_from_matrix
from posekit.profiler import NoiseModel, bundled_gauge, estimate_pose, nominal_pose, render_profiles
from posekit.profiler.stream.lines import encode_command
from posekit.profiler.stream.pose_filter import ConstantVelocityFilter, WindowFusion, make_filter

PERIOD_S = 0.012
COUNT = 300
SETTLE = 100          # estimates before the filters are compared (the CV filter converges in ~50)


def _errors(Ts, T_true):
    """Left errors [δt (mm), δθ (rad)] of poses (K, 4, 4) about the truth, in G."""
    Ts = np.asarray(Ts)
    T_true = np.broadcast_to(T_true, Ts.shape)
    out = np.empty((len(Ts), 6))
    out[:, :3] = Ts[:, :3, 3] - T_true[:, :3, 3]
    out[:, 3:] = rotation_vector_from_matrix(Ts[:, :3, :3] @ np.swapaxes(T_true[:, :3, :3], 1, 2))
    return out


@pytest.fixture(scope="module")
def gauge():
    return bundled_gauge("demo-5")


@pytest.fixture(scope="module")
def at_rest(gauge):
    """COUNT estimates (pose, covariance) of the gauge at rest at the nominal pose (LJ-X8400 noise)."""
    T = nominal_pose(gauge)
    profiles = render_profiles(gauge, np.repeat(T[None], COUNT, axis=0), NoiseModel(), rng=11)
    ests = [estimate_pose(p, gauge)[1] for p in profiles]
    return T, [e.T_G_F for e in ests], [e.cov for e in ests]


def _run(pose_filter, Ts, covs, t0=0.0):
    return [pose_filter.update(t0 + k * PERIOD_S, T, C) for k, (T, C) in enumerate(zip(Ts, covs))]


@pytest.mark.parametrize("pose_filter, min_ratio", [(ConstantVelocityFilter(), 6.0), (WindowFusion(10), 6.0)],
                         ids=["cv", "window"])
def test_filter_reduces_the_weak_y_and_rx_variance_at_rest(at_rest, pose_filter, min_ratio):
    T, Ts, covs = at_rest
    out = _run(pose_filter, Ts, covs)
    assert out[0].status == "init" and all(o.status == "ok" for o in out[1:])
    raw = _errors(Ts, T)[SETTLE:]
    filt = _errors([o.T_G_F for o in out], T)[SETTLE:]
    ratio = raw.var(axis=0) / filt.var(axis=0)
    # y (index 1) and the tilt about x (index 3) are the weak, anti-correlated pair; measured: cv 9.7x, window 8.3x
    assert ratio[1] > min_ratio and ratio[3] > min_ratio, ratio
    assert np.all(ratio > 1.0), ratio                          # and nothing gets worse
    # The filter's covariance is honest: ~95 % of the errors within 2 sigma (errors are correlated in
    # time, so the tolerance is wide), and it claims the gain it delivers.
    std = np.array([np.sqrt(np.diag(o.cov)) for o in out])[SETTLE:]
    inside = (np.abs(filt) <= 2 * std).mean(axis=0)
    assert np.all(inside > 0.85), inside
    raw_std = np.array([np.sqrt(np.diag(C)) for C in covs])[SETTLE:]
    assert np.median(raw_std[:, 1] / std[:, 1]) > 2.0


def test_filter_record_is_json_with_the_covariance(at_rest):
    T, Ts, covs = at_rest
    rec = _run(ConstantVelocityFilter(), Ts[:5], covs[:5])[-1].to_record()
    assert set(rec) == {"status", "t_mm", "q_wxyz", "std_t_um", "std_rot_deg", "cov", "v_mm_s", "w_rad_s", "nis",
                        "count"}
    back = json.loads(encode_command(rec))
    C = np.array(back["cov"])
    assert C.shape == (6, 6) and np.allclose(C, C.T) and np.all(np.linalg.eigvalsh(C) > 0)
    assert back["std_t_um"] == pytest.approx(list(np.sqrt(np.diag(C)[:3]) * 1e3))
    assert back["count"] == 5 and back["status"] == "ok"


def test_a_step_resets_the_filter_and_it_follows(gauge, at_rest):
    T, Ts, covs = at_rest
    step = np.eye(4)
    step[:3, 3] = [1.0, 0.0, 0.0]                              # the robot jumps 1 mm along x
    moved = [step @ X for X in Ts[100:160]]
    for pose_filter in (ConstantVelocityFilter(), WindowFusion(10)):
        out = _run(pose_filter, Ts[:100] + moved, covs[:160])
        statuses = [o.status for o in out[100:]]
        assert "reset" in statuses[:3], statuses[:5]           # CV: after max_rejects = 3; window: at once
        assert "reset" not in statuses[5:]
        err = _errors([o.T_G_F for o in out[110:]], step @ T)
        assert np.abs(err[:, 0]).max() < 0.05                  # back on the new pose (x to 50 µm)


def test_cv_filter_follows_a_ramp_without_lag(gauge):
    T0 = nominal_pose(gauge)
    v_mm_s = np.array([5.0, 0.0, -2.0])
    Ts = np.repeat(T0[None], 200, axis=0)
    Ts[:, :3, 3] += np.arange(200)[:, None] * PERIOD_S * v_mm_s
    ests = [estimate_pose(p, gauge)[1] for p in render_profiles(gauge, Ts, NoiseModel(), rng=3)]
    out = _run(ConstantVelocityFilter(), [e.T_G_F for e in ests], [e.cov for e in ests])
    assert all(o.status in ("init", "ok") for o in out)
    err = _errors([o.T_G_F for o in out[100:]], Ts[100:])
    std = np.array([np.sqrt(np.diag(o.cov)) for o in out[100:]])
    assert abs(err[:, 0].mean()) < 0.5 * std[:, 0].mean()     # no lag bias along the motion
    assert out[-1].velocity[:3] == pytest.approx(v_mm_s, abs=0.5)


def test_a_gap_or_time_going_back_restarts(at_rest):
    T, Ts, covs = at_rest
    f = ConstantVelocityFilter(max_gap_s=0.1)
    assert [f.update(t, Ts[0], covs[0]).status for t in (0.0, 0.012, 0.5, 0.4, 0.412)] == \
        ["init", "ok", "init", "init", "ok"]
    w = WindowFusion(5, max_gap_s=0.1)
    assert [w.update(t, Ts[0], covs[0]).count for t in (0.0, 0.012, 0.024, 0.2, 0.212)] == [1, 2, 3, 1, 2]


def test_window_holds_k_estimates(at_rest):
    T, Ts, covs = at_rest
    out = _run(WindowFusion(4), Ts[:10], covs[:10])
    assert [o.count for o in out] == [1, 2, 3, 4, 4, 4, 4, 4, 4, 4]


@pytest.mark.parametrize("build, message", [
    (lambda: ConstantVelocityFilter(accel_mm_s2=0.0), "ConstantVelocityFilter: accel_mm_s2 must be a finite number > 0, got 0.0"),
    (lambda: ConstantVelocityFilter(max_rejects=0), "ConstantVelocityFilter: max_rejects must be an integer >= 1, got 0"),
    (lambda: WindowFusion(0), "WindowFusion: k must be an integer in 1..10000, got 0"),
    (lambda: make_filter("ekf"), "unknown pose filter 'ekf'; expected one of cv, window"),
])
def test_bad_parameters_are_one_line_errors(build, message):
    with pytest.raises(ConfigError) as info:
        build()
    assert str(info.value) == message


def test_bad_estimates_are_refused(at_rest):
    T, Ts, covs = at_rest
    f = ConstantVelocityFilter()
    with pytest.raises(ConfigError) as info:
        f.update(0.0, Ts[0], np.full((6, 6), np.nan))
    assert str(info.value) == ("pose filter: the pose and its covariance must be finite (the closed form 'cf' has "
                               "no covariance: use the 'mle' method)")
    with pytest.raises(ConfigError, match=r"expected T_G_F of shape \(4, 4\) and cov \(6, 6\), got \(3, 3\)"):
        f.update(0.0, np.eye(3), covs[0])
