"""Hand-eye ``A X = Z B``: the closed form against a test-local Tsai-Lenz, the joint refinement on a
simulated eye-in-hand mount (240 mm lever arm, stereo-like noise worst in depth, clock offset,
outliers), the verdict on good and bad data, the reported std against the true error, the CLI.

The simulator here is written for this test (Euler-angle sinusoids about three axes, noise added in
the camera frame) and shares no code with posekit's.
"""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from posekit.cli.main import main
from posekit.errors import TrajectoryError
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.formats.tum import write_tum
from posekit.localcal.registration.handeye import calibrate_handeye
from posekit.localcal.registration.handeye_closed import park_martin, solve_world
from posekit.localcal.registration.handeye_time import PoseInterpolator

KEYS = ["R_tool_camera", "t_tool_camera_mm", "R", "t_mm", "rmse_mm", "status", "reasons", "std_rot_deg", "std_t_mm"]


def _T(R, t):
    T = np.zeros(np.broadcast_shapes(np.shape(R)[:-2], np.shape(t)[:-1]) + (4, 4))
    T[..., :3, :3], T[..., :3, 3], T[..., 3, 3] = R, t, 1.0
    return T


def _mount(rng, lever_mm=240.0):
    """Random X = T_tool_camera with |t| = lever_mm and Z = T_base_world."""
    d = rng.normal(size=3)
    X = _T(Rotation.random(random_state=rng).as_matrix(), lever_mm * d / np.linalg.norm(d))
    Z = _T(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-2000, 2000, 3))
    return X, Z


def eye_in_hand(seed, *, duration_s=12.0, lever_mm=240.0, offset_s=0.061, noise_mm=1.0, depth_factor=3.0,
                noise_deg=0.15, kin_noise_mm=0.05, outliers=0.0, axes="xyz", cam_hz=30.0, kin_hz=100.0,
                drift_mm=0.0):
    """(camera Trajectory T_world_camera, kinematic Trajectory T_base_tool, X, Z).

    The tool follows Euler-angle sinusoids (about ``axes`` only) and a Lissajous position; the
    camera clock reads tool time - offset_s; camera noise in the camera frame with
    ``depth_factor`` times more along the optical axis z; ``outliers`` of the camera positions
    jump by 0.2-0.5 m (relocalisation); ``drift_mm`` per sqrt(s) random-walk drift of the VO world.
    """
    rng = np.random.default_rng(seed)
    X, Z = _mount(rng, lever_mm)
    amp = np.deg2rad(rng.uniform(15, 30, 3)) * np.array([c in axes for c in "xyz"])
    w = rng.uniform(0.5, 1.2, 3)
    ph = rng.uniform(0, 2 * np.pi, 3)
    R0 = Rotation.random(random_state=rng)
    c = np.array([2500.0, 300.0, 900.0])

    def tool(t):
        eul = amp * np.sin(w * t[:, None] + ph)
        R = (R0 * Rotation.from_euler("xyz", eul)).as_matrix()
        p = c + np.c_[300 * np.sin(0.4 * t), 200 * np.sin(0.7 * t + 1), 150 * np.cos(0.3 * t)]
        return _T(R, p)

    t_kin = np.arange(0.0, duration_s, 1.0 / kin_hz)
    A = tool(t_kin)
    A[:, :3, 3] += rng.normal(0, kin_noise_mm, (t_kin.size, 3))
    t_cam = np.arange(0.5, duration_s - 0.5, 1.0 / cam_hz)
    B = np.linalg.inv(Z) @ tool(t_cam + offset_s) @ X
    e = rng.normal(0, noise_mm, (t_cam.size, 3)) * [1.0, 1.0, depth_factor]
    B[:, :3, 3] += np.einsum("kab,kb->ka", B[:, :3, :3], e)
    B[:, :3, :3] = B[:, :3, :3] @ Rotation.from_rotvec(rng.normal(0, np.deg2rad(noise_deg), (t_cam.size, 3))).as_matrix()
    if drift_mm:
        B[:, :3, 3] += np.cumsum(rng.normal(0, drift_mm / np.sqrt(cam_hz), (t_cam.size, 3)), axis=0)
    if outliers:
        k = rng.random(t_cam.size) < outliers
        B[k, :3, 3] += rng.uniform(200, 500, (k.sum(), 3)) * rng.choice([-1, 1], (k.sum(), 3))
    return Trajectory(t_cam, B), Trajectory(t_kin, A), X, Z


def tsai_lenz(A, B):
    """Tsai & Lenz (1989) hand-eye X from relative motions of consecutive poses (test-local,
    independent of posekit: modified Rodrigues vectors and a skew-symmetric linear system)."""
    def skew(v):
        return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    rows, rhs, Ms, ts = [], [], [], []
    for i in range(len(A) - 1):
        for j in range(i + 1, min(i + 8, len(A))):
            Ai, Bi = np.linalg.inv(A[i]) @ A[j], np.linalg.inv(B[i]) @ B[j]
            ra, rb = Rotation.from_matrix(Ai[:3, :3]).as_rotvec(), Rotation.from_matrix(Bi[:3, :3]).as_rotvec()
            th_a = np.linalg.norm(ra)
            if th_a < np.deg2rad(5):
                continue
            pa = 2 * np.sin(np.linalg.norm(ra) / 2) * ra / np.linalg.norm(ra)
            pb = 2 * np.sin(np.linalg.norm(rb) / 2) * rb / np.linalg.norm(rb)
            rows.append(skew(pa + pb))
            rhs.append(pb - pa)
            Ms.append(Ai)
            ts.append(Bi)
    pcg_ = np.linalg.lstsq(np.vstack(rows), np.hstack(rhs), rcond=None)[0]
    pcg = 2 * pcg_ / np.sqrt(1 + pcg_ @ pcg_)
    n2 = pcg @ pcg
    R = (1 - n2 / 2) * np.eye(3) + 0.5 * (np.outer(pcg, pcg) + np.sqrt(4 - n2) * skew(pcg))
    M = np.vstack([Ai[:3, :3] - np.eye(3) for Ai in Ms])
    b = np.hstack([R @ Bi[:3, 3] - Ai[:3, 3] for Ai, Bi in zip(Ms, ts)])
    return _T(R, np.linalg.lstsq(M, b, rcond=None)[0])


def _rot_err_deg(Ra, Rb):
    return float(np.rad2deg(Rotation.from_matrix(Ra @ Rb.T).magnitude()))


def _discrete_poses(seed, n=40, noise_mm=0.0, noise_deg=0.0):
    rng = np.random.default_rng(seed)
    X, Z = _mount(rng)
    A = _T(Rotation.random(n, random_state=rng).as_matrix(), rng.uniform(-800, 800, (n, 3)))
    B = np.linalg.inv(Z) @ A @ X
    B[:, :3, 3] += rng.normal(0, noise_mm, (n, 3))
    B[:, :3, :3] = B[:, :3, :3] @ Rotation.from_rotvec(rng.normal(0, np.deg2rad(noise_deg), (n, 3))).as_matrix()
    return A, B, X, Z


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_form_matches_truth_and_tsai_lenz_without_noise(seed):
    A, B, X, Z = _discrete_poses(seed)
    Xp = park_martin(A, B)
    Xt = tsai_lenz(A, B)
    np.testing.assert_allclose(Xp, X, atol=1e-8)
    np.testing.assert_allclose(Xt, X, atol=1e-8)
    np.testing.assert_allclose(solve_world(A, Xp, B), Z, atol=1e-8)


def test_closed_form_agrees_with_tsai_lenz_on_noisy_poses():
    A, B, X, Z = _discrete_poses(7, n=60, noise_mm=1.0, noise_deg=0.1)
    Xp, Xt = park_martin(A, B), tsai_lenz(A, B)
    assert _rot_err_deg(Xp[:3, :3], Xt[:3, :3]) < 0.05
    assert np.linalg.norm(Xp[:3, 3] - Xt[:3, 3]) < 1.0
    assert _rot_err_deg(Xp[:3, :3], X[:3, :3]) < 0.05
    assert np.linalg.norm(Xp[:3, 3] - X[:3, 3]) < 1.0


def test_pose_interpolator_agrees_with_scipy_slerp():
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.005, 0.02, 50))
    R = Rotation.random(50, random_state=rng)
    T = _T(R.as_matrix(), rng.normal(size=(50, 3)))
    tq = rng.uniform(t[0], t[-1], 200)
    got = PoseInterpolator(t, T)(tq)
    np.testing.assert_allclose(got[:, :3, :3], Slerp(t, R)(tq).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(got[:, :3, 3], np.stack([np.interp(tq, t, T[:, i, 3]) for i in range(3)], 1), atol=1e-12)


def test_eye_in_hand_240mm_lever_recovered_with_clock_offset_and_outliers():
    cam, kin, X, Z = eye_in_hand(11, outliers=0.1)
    res = calibrate_handeye(cam, kin)
    assert res.status == "ok", res.reasons
    # errors measured on this mount: ~0.02 deg / 0.3 mm (X), ~0.02 deg / 0.5 mm (Z)
    assert _rot_err_deg(res.T_tool_camera[:3, :3], X[:3, :3]) < 0.06
    assert np.linalg.norm(res.T_tool_camera[:3, 3] - X[:3, 3]) < 1.0
    assert _rot_err_deg(res.T_base_world[:3, :3], Z[:3, :3]) < 0.06
    assert np.linalg.norm(res.T_base_world[:3, 3] - Z[:3, 3]) < 2.0
    assert res.time_offset_s == pytest.approx(0.061, abs=0.002)     # match's position-based search: 61 ms off
    assert 0.85 < res.inliers.mean() < 0.95                          # the 10 % jumps are rejected
    err_t = np.abs(res.T_tool_camera[:3, 3] - X[:3, 3])
    assert np.all(err_t < 4 * res.std_t_mm)
    assert np.all(res.std_t_mm < 1.0) and np.all(res.std_rot_deg < 0.05)


def test_reported_std_covers_the_true_error():
    """On simulated mounts |error| < 2 std for about 95 % of the components (X and Z, 12 each)."""
    z = []
    for seed in range(20, 28):
        cam, kin, X, Z = eye_in_hand(seed, duration_s=6.0)
        r = calibrate_handeye(cam, kin)
        wx = np.rad2deg(Rotation.from_matrix(r.T_tool_camera[:3, :3] @ X[:3, :3].T).as_rotvec())
        wz = np.rad2deg(Rotation.from_matrix(r.T_base_world[:3, :3] @ Z[:3, :3].T).as_rotvec())
        z.append(np.abs(np.r_[wx / r.std_rot_deg, (r.T_tool_camera[:3, 3] - X[:3, 3]) / r.std_t_mm,
                              wz / r.std_world_rot_deg, (r.T_base_world[:3, 3] - Z[:3, 3]) / r.std_world_t_mm]))
    z = np.array(z)
    assert (z < 2).mean() >= 0.88
    assert (z < 3).mean() >= 0.97
    assert (z < 0.5).mean() >= 0.2          # not absurdly pessimistic either


def test_good_mounts_are_ok():
    # more good cases (status only) in test_localcal_handeye_study.py
    for seed, kw in [(33, {"lever_mm": 600.0, "noise_mm": 2.0}), (35, {"offset_s": -0.3})]:
        cam, kin, X, _ = eye_in_hand(seed, duration_s=6.0, **kw)
        res = calibrate_handeye(cam, kin)
        assert res.status == "ok", (seed, res.reasons)
        err = res.T_tool_camera[:3, 3] - X[:3, 3]
        assert np.linalg.norm(err) < 5.0 and np.all(np.abs(err) < 4 * res.std_t_mm), (seed, err, res.std_t_mm)
        assert res.time_offset_s == pytest.approx(kw.get("offset_s", 0.061), abs=0.003)


def test_rotation_about_one_axis_is_suspect():
    cam, kin, _, _ = eye_in_hand(40, duration_s=6.0, axes="z")
    res = calibrate_handeye(cam, kin)
    assert res.status == "suspect"
    assert res.reasons[0].startswith("the tool rotates about one axis only (")
    assert res.reasons[0].endswith("the camera offset along that axis is undetermined; rotate about >= 2 "
                                   "non-parallel axes")
    assert res.std_t_mm.max() > 100.0                # the undetermined direction shows in the std


def test_units_mismatch_is_suspect_with_a_hint():
    cam, kin, _, _ = eye_in_hand(41, duration_s=6.0)
    mm = Trajectory(cam.t_s, cam.T.copy())
    mm.T[:, :3, 3] *= 1000.0
    res = calibrate_handeye(mm, kin, names=("cam.tum", "kin.tum"))
    assert res.status == "suspect"
    assert any(r.endswith("is cam.tum in mm instead of m?") for r in res.reasons), res.reasons
    km = Trajectory(kin.t_s, kin.T.copy())
    km.T[:, :3, 3] *= 1000.0
    res = calibrate_handeye(cam, km, names=("cam.tum", "kin.tum"))
    assert any(r.endswith("is kin.tum in mm instead of m?") for r in res.reasons), res.reasons


def test_inconsistent_or_too_few_pairs_are_suspect():
    cam, kin, _, _ = eye_in_hand(42, duration_s=6.0)
    other, _, _, _ = eye_in_hand(43, duration_s=6.0)             # a camera that saw another motion
    res = calibrate_handeye(other, kin, time_offset_s=0.061)
    assert res.status == "suspect"
    assert any(r.startswith("position residuals") for r in res.reasons), res.reasons
    inv = Trajectory(cam.t_s, np.linalg.inv(cam.T))              # T_camera_world written instead
    assert calibrate_handeye(inv, kin).status == "suspect"
    few = Trajectory(cam.t_s[::16], cam.T[::16])
    res = calibrate_handeye(few, kin, time_offset_s=0.061)
    assert f"only {len(few)} pose pairs (expected >= 20)" in res.reasons
    with pytest.raises(TrajectoryError) as exc:
        calibrate_handeye(Trajectory(cam.t_s[:5] + 100.0, cam.T[:5]), kin, time_offset_s=0.0, names=("c", "k"))
    assert str(exc.value) == "c and k: 0 pose pairs within 0.02 s at a clock offset of +0.0 ms; hand-eye needs >= 3 " \
                             "(expected >= 20)"


def test_cli_writes_the_contract_and_exits_1_on_suspect(tmp_path, capsys):
    cam, kin, X, Z = eye_in_hand(50, duration_s=6.0)
    write_tum(tmp_path / "cam.tum", cam)
    write_tum(tmp_path / "kin.tum", kin)
    out = tmp_path / "he.json"
    assert main(["localcal", "handeye", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert list(res)[:9] == KEYS
    assert res["status"] == "ok" and res["reasons"] == []
    assert np.linalg.norm(np.array(res["t_tool_camera_mm"]) - X[:3, 3]) < 2.0
    assert _rot_err_deg(np.array(res["R"]), Z[:3, :3]) < 0.1
    assert "hand-eye from " in capsys.readouterr().out
    one = eye_in_hand(51, duration_s=6.0, axes="y")
    write_tum(tmp_path / "cam1.tum", one[0])
    write_tum(tmp_path / "kin1.tum", one[1])
    out1 = tmp_path / "he1.json"
    assert main(["localcal", "handeye", str(tmp_path / "cam1.tum"), str(tmp_path / "kin1.tum"), "--out", str(out1)]) == 1
    assert json.loads(out1.read_text())["status"] == "suspect"
    err = capsys.readouterr().err
    assert err.startswith("posekit: suspect hand-eye: the tool rotates about one axis only") and err.count("\n") == 1


def test_cli_bad_input_is_one_line(tmp_path, capsys):
    (tmp_path / "bad.tum").write_text("0 0 0 0 0 0 0 1\n1 0 0\n")
    write_tum(tmp_path / "kin.tum", eye_in_hand(52, duration_s=3.0)[1])
    rc = main(["localcal", "handeye", str(tmp_path / "bad.tum"), str(tmp_path / "kin.tum"), "--out",
               str(tmp_path / "o.json")])
    assert rc == 1
    assert capsys.readouterr().err == (f"posekit: error: {tmp_path / 'bad.tum'}:2: expected 8 numbers 'timestamp tx "
                                       "ty tz qx qy qz qw', found 3 fields\n")
    assert not (tmp_path / "o.json").exists()
    rc = main(["localcal", "handeye", str(tmp_path / "kin.tum"), str(tmp_path / "kin.tum"), "--out",
               str(tmp_path / "o.json"), "--noise-mm", "0"])
    assert rc == 1 and capsys.readouterr().err.startswith("posekit: error: --noise-mm: expected")


def accuracy_study(runs: int, **kw):
    """Errors and std coverage of ``calibrate_handeye`` over ``runs`` simulated mounts (seeds 1000+)."""
    err, z, status = [], [], []
    for seed in range(1000, 1000 + runs):
        cam, kin, X, Z = eye_in_hand(seed, **kw)
        r = calibrate_handeye(cam, kin)
        wx = np.rad2deg(Rotation.from_matrix(r.T_tool_camera[:3, :3] @ X[:3, :3].T).as_rotvec())
        wz = np.rad2deg(Rotation.from_matrix(r.T_base_world[:3, :3] @ Z[:3, :3].T).as_rotvec())
        tx, tz = r.T_tool_camera[:3, 3] - X[:3, 3], r.T_base_world[:3, 3] - Z[:3, 3]
        err.append([np.linalg.norm(wx), np.linalg.norm(tx), np.linalg.norm(wz), np.linalg.norm(tz),
                    abs(r.time_offset_s - kw.get("offset_s", 0.061)) * 1000])
        z.append(np.abs(np.r_[wx / r.std_rot_deg, tx / r.std_t_mm, wz / r.std_world_rot_deg, tz / r.std_world_t_mm]))
        status.append(r.status)
    return np.array(err), np.array(z), status


if __name__ == "__main__":
    import sys

    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    for label, kw in [("240 mm lever, 1 mm (3 mm in depth) + 0.15 deg VO noise, 61 ms offset", {}),
                      ("same + 10 % relocalisation jumps", {"outliers": 0.1}),
                      ("same + VO drift 1 mm/sqrt(s)", {"drift_mm": 1.0})]:
        e, z, st = accuracy_study(runs, **kw)
        print(f"{label}: {runs} runs of 12 s, ok {st.count('ok')}")
        print("  error median / 95th pct: X rot %.4f / %.4f deg, X t %.3f / %.3f mm; Z rot %.4f / %.4f deg, "
              "Z t %.3f / %.3f mm; offset %.2f / %.2f ms" % tuple(np.r_[[np.percentile(e[:, i], [50, 95])
                                                                      for i in range(5)]].ravel()))
        print("  |error| within 2 std: X %.3f, Z %.3f; within 3 std: X %.3f, Z %.3f" % (
            (z[:, :6] < 2).mean(), (z[:, 6:] < 2).mean(), (z[:, :6] < 3).mean(), (z[:, 6:] < 3).mean()))


def test_real_tum_pair_camera_is_at_the_ground_truth_body():
    """TUM RGB-D fr2/desk: ORB-SLAM2 camera poses against motion-capture poses of the same camera's
    optical centre (tests/data/tum/README.md), so the true mount is the identity up to the
    benchmark's own calibration (mm, a fraction of a degree)."""
    from posekit.localcal.registration.formats.tum import read_tum
    from tests.localcal.synth_trajectories import TUM_DATA as data

    cam, gt = read_tum(data / "fr2_desk_ORB.txt"), read_tum(data / "fr2_desk_groundtruth.txt")
    res = calibrate_handeye(cam, gt, max_dt_s=0.01, noise_mm=10.0, noise_deg=1.0)
    assert res.status == "ok", res.reasons
    assert res.n_pairs == 2170           # 2167 before the offset's derivative was taken on relative times
    X = res.T_tool_camera
    assert np.linalg.norm(X[:3, 3]) < 10.0                       # measured 6.4 mm
    assert _rot_err_deg(X[:3, :3], np.eye(3)) < 1.5               # measured 0.87 deg
    assert np.all(np.abs(X[:3, 3]) < 3 * res.std_t_mm)
    assert abs(res.time_offset_s) < 0.02


# --------------------------------------------------------------------------- clock offsets the data cannot measure
def stop_and_go(seed, n=40, dense=True):
    """A tool that holds a station for 0.6 s and moves (smoothstep) for 0.4 s, n times; the camera
    captures each station 0.3 s after arriving (1 s apart). ``dense``: the kinematic log at 100 Hz;
    otherwise one kinematic pose per capture (a robot that reports its pose at each stop)."""
    rng = np.random.default_rng(seed)
    X, Z = _mount(rng)
    R0, rv = Rotation.random(random_state=rng), rng.normal(0, 0.4, (n, 3))
    P = np.array([2500.0, 300.0, 900.0]) + rng.normal(0, 200, (n, 3))

    def tool(t):
        k = np.clip(np.floor(t).astype(int), 0, n - 1)
        f = np.clip((t - k - 0.6) / 0.4, 0, 1)
        f = 3 * f ** 2 - 2 * f ** 3
        k2 = np.minimum(k + 1, n - 1)
        return _T((R0 * Rotation.from_rotvec(rv[k] * (1 - f[:, None]) + rv[k2] * f[:, None])).as_matrix(),
                  P[k] * (1 - f[:, None]) + P[k2] * f[:, None])

    t_cap = np.arange(n) + 0.3
    t_kin = np.arange(0, n, 0.01) if dense else t_cap.copy()
    B = np.linalg.inv(Z) @ tool(t_cap) @ X
    B[:, :3, 3] += rng.normal(0, 1.0, (n, 3))
    B[:, :3, :3] = B[:, :3, :3] @ Rotation.from_rotvec(rng.normal(0, np.deg2rad(0.1), (n, 3))).as_matrix()
    return Trajectory(t_cap, B), Trajectory(t_kin, tool(t_kin)), X, Z


@pytest.mark.parametrize("dense", [True, False], ids=["log at 100 Hz", "one pose per capture"])
def test_stop_and_go_captures_leave_the_offset_undetermined(dense):
    """Before: 'one pose per capture' gave a confident +0.2 ms (std 0.24 ms) from interpolating across
    1 s gaps, and the 100 Hz log a 'weakly determined' suspect at -90 ms. The mount is good in both."""
    cam, kin, X, Z = stop_and_go(1, dense=dense)
    res = calibrate_handeye(cam, kin, names=("cam", "kin"))
    assert res.time_offset_source == "undetermined" and np.isnan(res.time_offset_s)
    assert res.status == "ok", res.reasons
    assert res.notes[0].startswith("kin holds one pose per cam pose (stop-and-go captures)" if not dense
                                   else "the clock offset is not determined by the data")
    assert np.linalg.norm(res.T_tool_camera[:3, 3] - X[:3, 3]) < 3 * np.linalg.norm(res.std_t_mm) + 0.5
    js = res.to_json()
    assert js["time_offset_s"] is None and js["time_offset_source"] == "undetermined"


def test_memory_follows_the_pairs_not_the_time_span():
    """One 1e6 s jump in the kinematic stamps: the angular-speed grid covers the data, not the gap
    (before: a grid of 1e8 points, past 6 GB). Peak traced memory of handeye and match < 100 MB."""
    import tracemalloc

    from posekit.localcal.registration.match import match_trajectories

    cam, kin, _, _ = eye_in_hand(3, duration_s=20.0)
    t = kin.t_s.copy()
    t[t.size // 2:] += 1e6
    kin = Trajectory(t, kin.T)
    for run in (lambda: calibrate_handeye(cam, kin), lambda: match_trajectories(cam, kin)):
        tracemalloc.start()
        try:
            res = run()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert res.n_pairs > 200
        assert peak < 100e6
