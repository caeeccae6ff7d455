"""The verdict of ``match_trajectories``: good data is never refused, every adversarial input of issue 14 is.

The cases are built here (on top of ``synth_trajectories``) and from the real TUM pairs. Print the
confusion table (good/bad x ok/suspect|error) over several seeds with::

    python -m tests.localcal.test_localcal_verdict 0 1 2 3 4
"""

import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.errors import TrajectoryError
from posekit.localcal.registration.match import match_trajectories
from posekit.localcal.registration.quality import check_units, lever_arm_fit
from posekit.localcal.registration.tum import Trajectory, read_tum
from tests.localcal.synth_trajectories import (
    TUM_DATA as DATA,
)
from tests.localcal.synth_trajectories import (
    asymmetric_planar_path,
    make_pair,
    random_transform,
    rotation_error_deg,
    smooth_path,
    stack_poses,
)


def base(seed, kind="smooth", **kw):
    """A camera/kinematic pair on a random smooth 3D path or the paper's planar path."""
    rng = np.random.default_rng(seed)
    pose, dur = (smooth_path(rng), 20.0) if kind == "smooth" else asymmetric_planar_path(rng)
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    opts = dict(offset_s=rng.uniform(-0.4, 0.4), outlier_fraction=0.05)
    opts.update(kw)
    src, dst = make_pair(rng, pose, dur, T_B_W=T, **opts)
    return src, dst, T, rng


def thin_path(seed, across_mm=40.0, noise_mm=1.0):
    """A planar path 500 mm along and ``across_mm`` (peak) across, rotating body."""
    rng = np.random.default_rng(seed)
    R0 = Rotation.random(random_state=rng).as_matrix()
    c = rng.uniform(-800, 800, 3)
    f1, f2 = rng.uniform(0.05, 0.1), rng.uniform(0.13, 0.3)
    ph = rng.uniform(0, 2 * np.pi, 2)

    def pose(t):
        p = np.c_[250 * np.sin(2 * np.pi * f1 * t + ph[0]), across_mm * np.sin(2 * np.pi * f2 * t + ph[1]), 0 * t]
        rv = 0.3 * np.c_[np.sin(0.2 * t), np.cos(0.13 * t), 0 * t]
        return p @ R0.T + c, (Rotation.from_matrix(R0) * Rotation.from_rotvec(rv)).as_matrix()
    T = random_transform(rng, c)
    src, dst = make_pair(rng, pose, 20.0, T_B_W=T, offset_s=rng.uniform(-0.3, 0.3), noise_mm=noise_mm)
    return src, dst, T


def correlated(seed, phi=0.97, sigma_mm=1.5):
    """Smooth path whose camera noise is AR(1) in time (VO drift that comes back), plus white noise."""
    src, dst, T, rng = base(seed, "smooth", outlier_fraction=0.0, noise_mm=0.3)
    e = np.zeros((len(src), 3))
    w = rng.normal(0, sigma_mm * np.sqrt(1 - phi ** 2), e.shape)
    for k in range(1, len(e)):
        e[k] = phi * e[k - 1] + w[k]
    W = src.T.copy()
    W[:, :3, 3] += e
    return Trajectory(src.t_s, W), dst, T


def lever(seed, lever_mm=(0.0, 80.0, 226.0), rot_scale=1.0):
    """Camera 240 mm from the tool (eye-in-hand) on a rotating path: src = T_W_tool @ T_tool_cam.

    ``rot_scale`` scales the path's orientation changes (1: +-0.4 rad about each axis)."""
    rng = np.random.default_rng(seed)
    path = smooth_path(rng)
    R_first = path(np.zeros(1))[1][0]

    def pose(t):
        p, R = path(t)
        rv = Rotation.from_matrix(R_first.T @ R).as_rotvec() * rot_scale
        return p, R_first @ Rotation.from_rotvec(rv).as_matrix()
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    X = np.eye(4)
    X[:3, :3] = Rotation.from_euler("xyz", [10, -5, 90], degrees=True).as_matrix()
    X[:3, 3] = lever_mm
    src, dst = make_pair(rng, pose, 20.0, T_B_W=T, offset_s=0.0)
    return Trajectory(src.t_s, src.T @ X), dst, T


def long_path(seed, duration_s=60.0):
    rng = np.random.default_rng(seed)
    pose = smooth_path(rng, duration_s=duration_s)
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    src, dst = make_pair(rng, pose, duration_s, T_B_W=T, offset_s=0.0)
    return src, dst, T


def _mode(ts):
    return "ts" if ts else "free"


def good_cases(seed):
    """(name, src, dst, kwargs, T_B_W or None) that must come out ``ok``."""
    if seed == 0:
        for nm, a, b in (("fr1", "freiburg1_xyz-rgbdslam.txt", "freiburg1_xyz-groundtruth.txt"),
                         ("fr2", "fr2_desk_ORB.txt", "fr2_desk_groundtruth.txt")):
            s, d = read_tum(DATA / a), read_tum(DATA / b)
            yield f"real {nm} ts", s, d, dict(max_dt_s=0.01), None
            yield f"real {nm} free", s, d, dict(use_timestamps=False), None
    for kind in ("smooth", "planar"):
        for ts in (True, False):
            src, dst, T, _ = base(seed, kind)
            yield f"{kind} 30/100 Hz, offset, 5% outliers {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T, _ = base(seed + 100, "smooth", outlier_fraction=0.2)
    yield "smooth 20% outliers ts", src, dst, dict(outlier_fraction=0.2), T
    src, dst, T, _ = base(seed + 100, "planar", outlier_fraction=0.2)
    yield "planar 20% outliers free", src, dst, dict(use_timestamps=False, outlier_fraction=0.2), T
    src, dst, T, _ = base(seed + 200, "smooth")
    keep = (src.t_s < src.t_s[0] + 6) | (src.t_s > src.t_s[0] + 9)
    gap = Trajectory(src.t_s[keep], src.T[keep])
    for ts in (True, False):
        yield f"smooth 3 s gap {_mode(ts)}", gap, dst, dict(use_timestamps=ts), T
    src, dst, T, rng = base(seed + 300, "smooth", outlier_fraction=0.0)
    W = src.T.copy()
    for a in rng.choice(np.arange(30, len(W) - 40), 2, replace=False):
        W[a:a + 12, :3, 3] += rng.normal(0, 150, 3)              # SLAM relocalisation: the map jumps and back
    for ts in (True, False):
        yield f"smooth relocalisation jumps {_mode(ts)}", Trajectory(src.t_s, W), dst, dict(use_timestamps=ts), T
    src, dst, T, _ = base(seed + 400, "smooth", offset_s=0.8 * (-1) ** seed)
    yield "smooth clock offset 0.8 s ts", src, dst, {}, T
    src, dst, T, _ = base(seed + 450, "planar", offset_s=0.137)
    yield "planar, the right --time-offset given", src, dst, dict(time_offset_s=0.137), T
    src, dst, T, _ = base(seed + 500, "planar", rate_src_hz=10.0, rate_dst_hz=250.0)
    for ts in (True, False):
        yield f"planar 10/250 Hz {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T = thin_path(seed + 600, across_mm=40.0)
    for ts in (True, False):
        yield f"weak: thin 500x80 mm path {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T = correlated(seed + 700)
    yield "smooth AR(1) camera noise ts", src, dst, {}, T
    src, dst, T = long_path(seed + 800)
    a = (src.t_s >= 3) & (src.t_s <= 13)
    yield "camera 3-13 s of 60 s ts", Trajectory(src.t_s[a], src.T[a]), dst, {}, T


def bad_cases(seed):
    """(name, src, dst, kwargs, T_B_W) of issue 14 that must not come out ``ok``."""
    src, dst, T = long_path(seed + 1000)
    a = (src.t_s >= 3) & (src.t_s <= 13)
    yield "camera 3-13 s of 60 s free", Trajectory(src.t_s[a], src.T[a]), dst, dict(use_timestamps=False), T
    src, dst, T, _ = base(seed + 1100, "smooth", outlier_fraction=0.0)
    k = np.linspace(0, len(src) - 1, 7).round().astype(int)
    yield "7 camera poses free", Trajectory(src.t_s[k], src.T[k]), dst, dict(use_timestamps=False), T
    src, dst, T, _ = base(seed + 1200, "smooth")
    M = np.diag([1.0, 1.0, -1.0])
    Wm = src.T.copy()
    Wm[:, :3, 3] = Wm[:, :3, 3] @ M
    Wm[:, :3, :3] = M @ Wm[:, :3, :3] @ M
    for ts in (True, False):
        yield f"mirrored {_mode(ts)}", Trajectory(src.t_s, Wm), dst, dict(use_timestamps=ts), T
    src, dst, T, _ = base(seed + 1300, "smooth")
    Wk = src.T.copy()
    Wk[:, :3, 3] *= 1000.0
    for ts in (True, False):
        yield f"camera file in mm {_mode(ts)}", Trajectory(src.t_s, Wk), dst, dict(use_timestamps=ts), T
    Bk = dst.T.copy()
    Bk[:, :3, 3] *= 1000.0
    yield "kinematic file in mm ts", src, Trajectory(dst.t_s, Bk), {}, T
    src, dst, T, _ = base(seed + 1400, "smooth")
    for ts in (True, False):
        yield f"inverted poses {_mode(ts)}", Trajectory(src.t_s, np.linalg.inv(src.T)), dst, dict(use_timestamps=ts), T
    src, dst, T = lever(seed + 1500)
    for ts in (True, False):
        yield f"camera 240 mm from tool {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T = lever(seed + 1550, rot_scale=0.15)
    for ts in (True, False):
        yield f"camera 240 mm from tool, gentle turns {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T = thin_path(seed + 1600, across_mm=6.0)
    for ts in (True, False):
        yield f"nearly straight path {_mode(ts)}", src, dst, dict(use_timestamps=ts), T
    src, dst, T, _ = base(seed + 1700, "smooth", offset_s=0.137)
    yield "--time-offset with the wrong sign", src, dst, dict(time_offset_s=-0.137), T
    src, dst, T, _ = base(seed + 1750, "planar", offset_s=0.137)     # constant orientation: no spread to see
    yield "--time-offset with the wrong sign, planar path", src, dst, dict(time_offset_s=-0.137), T
    src, dst, T, rng = base(seed + 1800, "smooth")
    lo, hi = src.positions.min(0), src.positions.max(0)
    Wr = stack_poses(rng.uniform(lo, hi, (len(src), 3)), Rotation.random(len(src), random_state=rng).as_matrix())
    for ts in (True, False):
        yield f"random positions {_mode(ts)}", Trajectory(src.t_s, Wr), dst, dict(use_timestamps=ts), T


def run_case(src, dst, kw):
    """(status or 'error', Registration or the error message)."""
    try:
        reg = match_trajectories(src, dst, names=("cam", "kin"), **kw)
    except TrajectoryError as exc:
        return "error", str(exc)
    return reg.status, reg


# ------------------------------------------------------------------ tests (seed 0)
@pytest.mark.parametrize("case", list(good_cases(0)), ids=lambda c: c[0])
def test_good_data_is_ok(case):
    name, src, dst, kw, T = case
    status, reg = run_case(src, dst, kw)
    assert status == "ok", reg if status == "error" else reg.reasons
    if T is not None:                                   # and the estimate is right
        assert rotation_error_deg(reg.R, T[:3, :3]) < 0.5
        assert np.linalg.norm(reg.t_mm - T[:3, 3]) < 5.0


BAD_MESSAGES = {
    "camera 3-13 s of 60 s free": r"the matched part covers only \d+% of kin's poses",
    "7 camera poses free": r"^only 7 poses in cam: correspondence-free matching needs at least 30; match with timestamps$",
    "mirrored ts": r"^cam looks mirrored \(a left-handed frame, one axis flipped\)",
    "mirrored free": r"^cam looks mirrored",
    "inverted poses ts": r"^cam looks inverted \(T_C_W, world in camera, written instead of T_W_C\)",
    "inverted poses free": r"^cam looks inverted",
    "camera 240 mm from tool ts": r"the camera looks 2\d\d mm from the tool point .*use `posekit localcal handeye`$",
    "camera 240 mm from tool free": r"use `posekit localcal handeye`$",
    "nearly straight path ts": r"^the matched path is nearly straight",
    "nearly straight path free": r"^the matched path is nearly straight",
    "--time-offset with the wrong sign": r"^the data fit a clock offset of \+0.13\d s .* better than the given -0.137 s: "
                                         r"check the sign of --time-offset \(t_kinematic - t_camera\)$",
    "--time-offset with the wrong sign, planar path": r"^the data fit a clock offset of \+0.13\d s",
    "random positions free": r"% of the path's extent",
}


@pytest.mark.parametrize("case", list(bad_cases(0)), ids=lambda c: c[0])
def test_adversarial_input_is_never_ok(case):
    import re
    name, src, dst, kw, T = case
    status, reg = run_case(src, dst, kw)
    assert status in ("suspect", "error")
    if name in BAD_MESSAGES:
        assert status == "suspect"
        assert any(re.search(BAD_MESSAGES[name], r) for r in reg.reasons), reg.reasons
    if name.startswith("camera file in mm"):
        assert reg == ("cam moves 1015x as far as kin (342 m vs 0.337 m along the main axis), not the same motion in "
                       "one unit; is it in millimetres? trajectory files are in metres; unknown scale: --with-scale")
    if name == "kinematic file in mm ts":      # no longer a misleading 'clock offset at the edge' error
        assert reg.startswith("kin moves 985x as far as cam") and "is it in millimetres?" in reg
    if name == "random positions ts":
        assert reg.startswith("no clock offset within ±1 s makes cam and kin agree")


def test_units_check_passes_a_scaled_monocular_trajectory_with_scale():
    src, dst, T, _ = base(5, "planar", offset_s=0.0)
    W = src.T.copy()
    W[:, :3, 3] *= 0.001                                          # 1000x smaller, e.g. monocular VO
    with pytest.raises(TrajectoryError, match=r"^kin moves 1010x as far as cam \(0.469 m vs 0.000464 m along the main axis\)"):
        check_units(W[:, :3, 3], dst.positions, ("cam", "kin"))
    reg = match_trajectories(Trajectory(src.t_s, W), dst, with_scale=True)
    assert reg.status == "ok" and reg.scale == pytest.approx(1000.0, rel=5e-3)


def test_lever_arm_fit_recovers_the_mount():
    """The lever-arm model is exact on noise-free data: an independent check of the hand-eye reason."""
    rng = np.random.default_rng(3)
    R_d = Rotation.random(200, random_state=rng).as_matrix()
    p_d = rng.normal(0, 300, (200, 3))
    y = np.array([20.0, -80.0, 226.0])
    R = Rotation.random(random_state=rng).as_matrix()
    t = np.array([100.0, 50.0, -20.0])
    p_s = (p_d - R_d @ y - t) @ R                           # p_d = R p_s + t + R_d y
    y_fit, rmse = lever_arm_fit(p_s, p_d, R_d)
    np.testing.assert_allclose(y_fit, y, atol=1e-6)
    assert rmse < 1e-6


def confusion(seeds):
    """Confusion table and per-case lines over ``seeds``; returns {(good, flagged): count}."""
    table = {}
    for seed in seeds:
        for good, gen in ((True, good_cases), (False, bad_cases)):
            for name, src, dst, kw, T in gen(seed):
                status, reg = run_case(src, dst, kw)
                flagged = status != "ok"
                table[(good, flagged)] = table.get((good, flagged), 0) + 1
                err = ""
                if status != "error" and T is not None:
                    err = f"{rotation_error_deg(reg.R, T[:3, :3]):7.2f} deg {np.linalg.norm(reg.t_mm - T[:3, 3]):8.1f} mm"
                why = reg if status == "error" else "; ".join(r[:60] for r in reg.reasons)
                if flagged == good:
                    print(f"seed {seed} {'good' if good else 'bad '} {name:40s} {status:8s} {err:24s} {why[:150]}")
    print(f"seeds {list(seeds)}: good->ok {table.get((True, False), 0)}, good->suspect/error "
          f"{table.get((True, True), 0)}, bad->ok {table.get((False, False), 0)}, bad->suspect/error "
          f"{table.get((False, True), 0)}")
    return table


if __name__ == "__main__":
    confusion([int(a) for a in sys.argv[1:]] or [0])
