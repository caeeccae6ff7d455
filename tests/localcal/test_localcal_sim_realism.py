"""The simulator's closer-to-the-paper models: stereo VO errors that grow with depth, lens
distortion in the rendered images, correspondence-free matching in an episode, Fig. 5.

The stereo formula is checked against an independent generator written here (features
triangulated from noisy disparities), the distortion against ``cv2.projectPoints``."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.geometry import invert_transform, matrix_from_rotation_vector
from posekit.localcal.model.camera import ZED2_720P_DISTORTION, CameraIntrinsics, zed2_720p
from posekit.localcal.sim.camera import _ideal_pixel_map, render_markers
from posekit.localcal.sim.marker_detector import MarkerDetector
from posekit.localcal.sim.vo import StereoNoise, depth_along_axis, simulate_vo

cv2 = pytest.importorskip("cv2")

QUIET = {"noise_mm": 0.0, "noise_rad": 0.0, "drift_mm_per_sqrt_m": 0.0, "drift_rad_per_sqrt_m": 0.0, "stride": 1}


def _line_path(n, step_mm=0.01):
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, 0, 3] = np.arange(n) * step_mm
    return T, np.arange(n) * 0.01


# --------------------------------------------------------------------------- stereo VO

def test_stereo_sigma_matches_triangulated_features():
    """Independent generator: n features at depth z, disparity d = f b / z with N(0, σ_d) noise,
    triangulated z' = f b / d'; the std of their mean depth is the model's depth sigma."""
    st = StereoNoise()
    rng = np.random.default_rng(0)
    for z in (500.0, 1000.0, 2000.0, 3000.0):
        d = st.focal_px * st.baseline_mm / z
        d_noisy = d + rng.normal(0.0, st.disparity_noise_px, (20000, st.features))
        mean_depth = (st.focal_px * st.baseline_mm / d_noisy).mean(axis=1)
        assert np.std(mean_depth) == pytest.approx(st.sigma_mm(z)[2], rel=0.05)
        # lateral: x = z u / f with N(0, σ_px) on u
        x = z * rng.normal(0.0, st.pixel_noise_px, (20000, st.features)) / st.focal_px
        assert np.std(x.mean(axis=1)) == pytest.approx(st.sigma_mm(z)[0], rel=0.05)
    # the reported numbers: depth error grows with z^2, lateral with z
    np.testing.assert_allclose(st.sigma_mm([500.0, 1000.0, 2000.0])[:, 2], [0.39, 1.58, 6.31], atol=0.01)
    np.testing.assert_allclose(st.sigma_mm(1000.0)[:2], [0.19, 0.19], atol=0.01)


def test_simulated_stereo_vo_noise_is_anisotropic_in_the_camera_frame():
    n = 4000
    T, t = _line_path(n)
    # camera rotated: its optical axis is the base x axis, so the depth error shows on W's z only
    R = matrix_from_rotation_vector([0.0, np.pi / 2, 0.0])
    T[:, :3, :3] = R
    st = StereoNoise(drift_mm_per_sqrt_m=0.0, drift_rad_per_sqrt_m=0.0, disparity_bias_px=0.0, corr_s=0.0)
    for z in (1000.0, 2000.0):
        vo = simulate_vo(T, t, 1, stereo=st, depth_mm=z, **QUIET)
        truth = invert_transform(T[0]) @ T
        e_C = np.einsum("nji,nj->ni", truth[1:, :3, :3], vo.T[1:, :3, 3] - truth[1:, :3, 3])
        np.testing.assert_allclose(e_C.std(axis=0), st.sigma_mm(z), rtol=0.06)


def test_frame_noise_is_correlated_with_the_time_constant():
    n = 20000
    T, t = _line_path(n)
    st = StereoNoise(drift_mm_per_sqrt_m=0.0, drift_rad_per_sqrt_m=0.0, disparity_bias_px=0.0, corr_s=0.2)
    vo = simulate_vo(T, t, 5, stereo=st, depth_mm=1500.0, **QUIET)
    e = vo.T[1:, 2, 3] - T[1:, 2, 3]
    assert np.std(e) == pytest.approx(st.sigma_mm(1500.0)[2], rel=0.1)
    lag = 10                                         # 0.1 s
    r = np.corrcoef(e[:-lag], e[lag:])[0, 1]
    assert r == pytest.approx(np.exp(-0.1 / 0.2), abs=0.05)


def test_disparity_bias_scales_the_vo_translation():
    n = 200
    T, t = _line_path(n, step_mm=2.0)
    st = StereoNoise(pixel_noise_px=0.0, disparity_noise_px=0.0, drift_mm_per_sqrt_m=0.0,
                     drift_rad_per_sqrt_m=0.0, disparity_bias_px=0.5)
    vo = simulate_vo(T, t, 3, stereo=st, depth_mm=1200.0, **QUIET)
    ratio = vo.T[1:, 0, 3] / T[1:, 0, 3]
    assert np.ptp(ratio) < 1e-12                     # one scale for the whole trajectory
    assert 1e-4 < abs(ratio[0] - 1.0) < 5 * 1200.0 * 0.5 / (528.0 * 120.0)


def test_stereo_drift_is_larger_along_the_optical_axis():
    n = 300
    T, t = _line_path(n, step_mm=5.0)               # 1.5 m of travel; camera axes = W axes
    st = StereoNoise(features=10**8, corr_s=0.0, disparity_bias_px=0.0, drift_rad_per_sqrt_m=0.0)
    ends = [simulate_vo(T, t, seed, stereo=st, depth_mm=2000.0, **QUIET).T[-1, :3, 3] - T[-1, :3, 3]
            for seed in range(200)]
    expect = st.drift_mm_per_sqrt_m * np.sqrt(1.5) * np.array([1.0, 1.0, 2000.0 / 120.0])   # depth: z / b times
    np.testing.assert_allclose(np.std(ends, axis=0), expect, rtol=0.2)


def test_stereo_vo_keeps_running_with_the_same_seed():
    T, t = _line_path(600, step_mm=1.0)
    z = np.linspace(800.0, 1500.0, 600)
    short = simulate_vo(T[:300], t[:300], 9, stereo=StereoNoise(), depth_mm=z[:300], stride=3)
    long = simulate_vo(T, t, 9, stereo=StereoNoise(), depth_mm=z, stride=3)
    np.testing.assert_allclose(long.T[:100], short.T, atol=1e-9)


def test_depth_along_the_optical_axis_to_a_wall():
    wall = np.eye(4)
    wall[:3, 3] = [0.0, 0.0, 2000.0]                # the plane z = 2000 mm, normal +z
    T = np.broadcast_to(np.eye(4), (2, 4, 4)).copy()
    T[1, :3, :3] = matrix_from_rotation_vector([np.deg2rad(60.0), 0.0, 0.0])
    T[1, :3, 3] = [0.0, 0.0, 500.0]
    np.testing.assert_allclose(depth_along_axis(T, wall), [2000.0, 1500.0 / np.cos(np.deg2rad(60.0))])


def test_bad_stereo_settings_are_one_line_errors():
    T, t = _line_path(10)
    with pytest.raises(ConfigError,
                       match=r"^simulate_vo: the stereo model needs depth_mm \(the scene depth per pose, mm\)$"):
        simulate_vo(T, t, 0, stereo=StereoNoise())
    with pytest.raises(ConfigError, match=r"^simulate_vo: depth_mm must be finite and > 0 \(mm\) at every pose$"):
        simulate_vo(T, t, 0, stereo=StereoNoise(), depth_mm=np.r_[np.ones(9), -1.0])
    with pytest.raises(ConfigError, match=r"^StereoNoise: features must be an integer >= 1, got 0$"):
        StereoNoise(features=0)
    with pytest.raises(ConfigError, match=r"^StereoNoise: baseline_mm must be a finite number > 0, got -1.0$"):
        StereoNoise(baseline_mm=-1.0)


# --------------------------------------------------------------------------- lens distortion

def test_projection_with_distortion_matches_opencv():
    intr = zed2_720p(distorted=True)
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-900, 900, 50), rng.uniform(-500, 500, 50), rng.uniform(800, 1500, 50)])
    ref, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), intr.K, np.array(ZED2_720P_DISTORTION))
    np.testing.assert_allclose(intr.project(p), ref.reshape(-1, 2), atol=1e-6)
    assert np.max(np.abs(intr.project(p) - intr.project(p, distort=False))) > 10.0   # px at the edges
    ideal, r2 = _ideal_pixel_map(intr)
    uv = np.array([[0, 0], [1279, 719], [640, 360], [100, 600]])
    xy = (ideal[uv[:, 1], uv[:, 0]].astype(np.float64) - [intr.cx, intr.cy]) / [intr.fx, intr.fy]
    back = intr.distort_normalized(xy) * [intr.fx, intr.fy] + [intr.cx, intr.cy]
    np.testing.assert_allclose(back, uv, atol=0.02)          # bilinear between exact 4 px nodes


def test_distorted_images_detected_with_the_lens_model_give_the_true_pose():
    """A marker near the image corner: detection that knows the distortion is as accurate as on a
    rectified image; one that ignores it sees the (barrel-shrunk) marker ~2 cm too far."""
    intr = zed2_720p(distorted=True)
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = [-700.0, 330.0, 1000.0]
    aware = MarkerDetector(intr, {1: 80.0})
    blind = MarkerDetector(zed2_720p(), {1: 80.0})
    err_aware, err_blind = [], []
    for seed in range(5):
        img = render_markers(intr, [(1, 80.0, T)], seed)
        err_aware.append(np.linalg.norm(aware.detect(img)[1][:3, 3] - T[:3, 3]))
        err_blind.append(np.linalg.norm(blind.detect(img)[1][:3, 3] - T[:3, 3]))
    assert np.mean(err_aware) < 12.0
    assert np.mean(err_blind) > np.mean(err_aware) + 12.0


def test_bad_distortion_is_a_config_error():
    with pytest.raises(ConfigError, match=r"^camera intrinsics: expected 5 finite distortion coefficients"):
        CameraIntrinsics(500.0, 500.0, 320.0, 240.0, 640, 480, distortion=(0.1, 0.0))


# --------------------------------------------------------------------------- episodes

def test_correspondence_free_episode_and_fig5(tmp_path):
    from posekit.localcal.studies.episode import run_localcal_episode
    from posekit.localcal.studies.episode_config import EpisodeConfig
    from posekit.localcal.studies.plots import plot_orientation_errors

    cfg = EpisodeConfig(camera_hz=2.0, plot_hz=1.0, use_timestamps=False)
    ep = run_localcal_episode("trajectory", 4, updates=2, config=cfg)
    assert ep.matching["mode"] == "no-timestamps"
    assert cfg.lens_distortion and cfg.vo_stereo is not None
    true_xy = np.abs(ep.true_errors_mm[-1, :2])
    assert np.all(true_xy < 10.0), true_xy
    rot = ep.timeline["rot_deg"]
    assert rot.shape == (len(ep.timeline["t_s"]), 3)
    first = np.flatnonzero(np.all(np.isfinite(rot), axis=1))[0]
    np.testing.assert_allclose(np.abs(rot[first]), ep.rotation_before_deg, atol=1e-9)
    path = plot_orientation_errors(ep, tmp_path / "fig5.png")
    assert path.stat().st_size > 1000


def test_tilted_calibration_path_rotates_the_inner_waypoints():
    from posekit.geometry import rotation_angle_between
    from posekit.localcal.methods.trajectory_method import asymmetric_path

    T = np.eye(4)
    flat = asymmetric_path(T)
    tilted = asymmetric_path(T, tilt_rad=np.deg2rad(10.0))
    np.testing.assert_allclose(tilted[:, :3, 3], flat[:, :3, 3])              # same positions (eq. 17-19)
    angles = np.degrees(rotation_angle_between(tilted[:, :3, :3], flat[:, :3, :3]))
    np.testing.assert_allclose(angles, [0.0, 10.0, 10.0, 10.0, 10.0, 10.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(tilted[1, :3, :3] @ [0.0, 0.0, 1.0],               # about n (x) first
                               [0.0, -np.sin(np.deg2rad(10.0)), np.cos(np.deg2rad(10.0))], atol=1e-12)
    with pytest.raises(ConfigError, match=r"^calibration path: tilt must be between 0 and pi/4 rad, got 1.0$"):
        asymmetric_path(T, tilt_rad=1.0)


def test_rotating_path_with_the_camera_off_the_tool_needs_hand_eye():
    """The camera is ~0.47 m from the tool point: on a tilting path the paper's position matching
    is centimetres off (and its verdict says so); hand-eye recovers sub-centimetre XY."""
    from posekit.localcal.studies.episode import run_localcal_episode
    from posekit.localcal.studies.episode_config import EpisodeConfig

    base = {"camera_hz": 2.0, "plot_hz": 0.0, "calibration_tilt_deg": 15.0}
    he = run_localcal_episode("trajectory", 2, updates=1, config=EpisodeConfig(**base))
    match = run_localcal_episode("trajectory", 2, updates=1, config=EpisodeConfig(**base, registration="match"))
    assert he.matching["mode"] == "handeye" and match.matching["mode"] == "timestamps"
    assert np.all(np.abs(he.true_errors_mm[0, :2]) < 10.0), he.true_errors_mm
    assert np.max(np.abs(match.true_errors_mm[0, :2])) > 30.0, match.true_errors_mm
    assert match.matching["status"] == "suspect"
    assert any("handeye" in r for r in match.matching["reasons"])
    np.testing.assert_allclose(np.linalg.norm(he.matching["t_tool_camera_mm"]), 473.0, atol=25.0)
    with pytest.raises(ConfigError, match=r"^registration: hand-eye calibration needs timestamps"):
        EpisodeConfig(registration="handeye", use_timestamps=False)
    with pytest.raises(ConfigError, match=r"^registration: expected one of auto \| match \| handeye, got 'x'$"):
        EpisodeConfig(registration="x")


def test_boom_vibration_is_the_damped_second_order_response():
    """Constant commanded acceleration of the lift joint from rest: the deflection follows the
    closed-form step response of δ̈ + 2ζωδ̇ + ω²δ = -gα; the encoders never see it."""
    from posekit.localcal.sim.arm import LongReachArm
    from posekit.localcal.sim.arm_errors import NonKinematicErrors

    errors = NonKinematicErrors(np.zeros(6), np.zeros(6), [0.0, 0.0], flex_hz=1.5, flex_damping=0.08, flex_gain=0.7)
    arm = LongReachArm(errors=errors, seed=0)
    dt, alpha, k = arm.dt_s, 0.05, np.arange(1, 301)
    q0 = arm._state["q_cmd"]
    q_cmd = np.broadcast_to(q0, (300, 6)).copy()
    q_cmd[:, 1] += 0.5 * alpha * (k * dt) ** 2             # q(t) = q0 + α t² / 2 for t >= 0
    arm._state["q_cmd_hist"][0, 1] += 0.5 * alpha * dt ** 2  # and at t = -dt: α from the first step on
    flex = arm._flex(q_cmd)
    w, z = 2 * np.pi * 1.5, 0.08
    wd = w * np.sqrt(1 - z * z)
    t = k * dt                                              # flex[k - 1] is the deflection after step k
    step = -0.7 * alpha / w ** 2 * (1 - np.exp(-z * w * t) * (np.cos(wd * t) + z / np.sqrt(1 - z * z) * np.sin(wd * t)))
    np.testing.assert_allclose(flex[:, 0], step, atol=1e-6 * 0.7 * alpha / w ** 2)
    assert np.all(flex[:, 1] == 0.0)                      # the tilt joint is not accelerated
    rigid = NonKinematicErrors(np.zeros(6), np.zeros(6), [0.0, 0.0])
    assert LongReachArm(errors=rigid, seed=0)._flex(q_cmd).max() == 0.0
