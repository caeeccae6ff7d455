"""A lens model the calibration points contradict (issue 28 item 10): CAMERA.json with k1's sign
flipped is ``suspect`` at ``ceiling calibrate`` (exit 1, the file written with the rows named),
and ``track`` never marks a row ``ok`` with such a calibration, whose ``std_mm`` then carries the
residual of all the points. Points made here: a grid through a homography and OpenCV's lens
model (``CameraModel.distort_points``), 0.2 px of click noise."""

import json

import numpy as np

from posekit.ceiling.camera.homography import Calibration, load_calibration
from posekit.ceiling.camera.lens import CameraModel, save_camera
from posekit.ceiling.camera.lens_check import calibrate_points
from posekit.ceiling.track.cameras import Camera
from posekit.ceiling.track.pipeline import track_frames
from tests.ceiling.test_track_scene import H_IMAGE_WORLD, Scene
from tests.cli_helpers import run_cli

W, H = 864, 480
K = np.array([[700.0, 0.0, 431.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]])
H_IW = np.array([[0.2, 0.004, 40.0], [-0.003, 0.19, 30.0], [1.0e-6, 2.0e-6, 1.0]])


def points(k1=-0.25, k2=0.05, seed=0):
    gx, gy = np.meshgrid(np.linspace(0, 3600, 8), np.linspace(0, 2000, 5))
    world = np.c_[gx.ravel(), gy.ravel()]
    q = np.c_[world, np.ones(len(world))] @ H_IW.T
    und = q[:, :2] / q[:, 2:]
    lens = CameraModel(K=K, dist=[k1, k2, 0, 0, 0], image_size=(W, H))
    seen = lens.distort_points(und) + np.random.default_rng(seed).normal(0, 0.2, und.shape)
    return world, seen, lens


def write_points(path, world, seen):
    path.write_text("X,Y,u,v\n" + "".join(f"{X:g},{Y:g},{u:.3f},{v:.3f}\n" for (X, Y), (u, v) in zip(world, seen)))


def test_flipped_k1_is_suspect_and_the_right_lens_is_ok(capsys, tmp_path):
    world, seen, lens = points()
    write_points(tmp_path / "pts.csv", world, seen)
    save_camera(lens, tmp_path / "right.json")
    save_camera(CameraModel(K=K, dist=[0.25, 0.05, 0, 0, 0], image_size=(W, H)), tmp_path / "flipped.json")
    rc, out, err = run_cli(capsys, "ceiling", "calibrate", tmp_path / "pts.csv", "--camera", tmp_path / "right.json",
                           "--out", tmp_path / "ok.json")
    assert rc == 0, err
    cal = load_calibration(tmp_path / "ok.json")
    assert cal.status == "ok" and cal.image_size == (W, H) and cal.rms_px < 0.4 and cal.inliers.all()
    rc, out, err = run_cli(capsys, "ceiling", "calibrate", tmp_path / "pts.csv", "--camera", tmp_path / "flipped.json",
                           "--out", tmp_path / "bad.json")
    assert rc == 1
    assert err.count("posekit: suspect: the points contradict the lens model") == 1 and "Traceback" not in err
    assert "rejected: line " in err                           # the offending rows are named
    bad = load_calibration(tmp_path / "bad.json")             # written all the same, marked
    assert bad.status == "suspect" and bad.reasons and bad.rms_all_px > 5 * bad.rms_px
    assert json.loads((tmp_path / "bad.json").read_text())["status"] == "suspect"


def test_library_verdict_without_a_lens_is_ok_and_names_nothing():
    world, seen, _ = points(k1=0.0, k2=0.0)
    cal, radial = calibrate_points(world, seen)
    assert cal.status == "ok" and cal.reasons == () and not radial.detected
    assert cal.points_extent[2] <= W and cal.image_size is None


def test_track_with_a_suspect_calibration_is_never_ok():
    sc = Scene(n=40, seed=4)
    good = Calibration(H_IMAGE_WORLD, np.linalg.inv(H_IMAGE_WORLD), 0.3, 3.0)
    bad = Calibration(H_IMAGE_WORLD, np.linalg.inv(H_IMAGE_WORLD), 0.3, 3.0, status="suspect",
                      reasons=("the points contradict the lens model",), rms_all_px=12.0)
    res_good = track_frames(sc.frames(), [Camera(good, (432, 240))], ("red",))
    res_bad = track_frames(sc.frames(), [Camera(bad, (432, 240))], ("red",))
    assert res_good.counts()["ok"] > 30 and res_good.counts()["suspect"] == 0
    assert res_bad.counts()["ok"] == 0 and res_bad.counts()["suspect"] == res_good.counts()["ok"]
    sus = [r for r in res_bad.rows if r.status == "suspect"]
    assert all("calibration: the points contradict the lens model" in r.reason for r in sus)
    std_good = np.median([r.std_mm for r in res_good.rows if r.status == "ok"])
    assert np.median([r.std_mm for r in sus]) > 10 * std_good      # 12 px of residual, not 0.3
