"""``posekit ceiling calibrate`` with a lens: --camera, per-point residuals, the radial-pattern
warning and RANSAC's reasons. Points come from OpenCV's projection (cv2.projectPoints), not from
the ceiling renderer."""

from functools import partial

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose

from posekit.ceiling.camera.homography import calibrate
from posekit.ceiling.camera.lens import CameraModel, save_camera
from posekit.ceiling.camera.lens_check import radial_pattern
from posekit.ceiling.camera.points import undistort_calibration_points
from posekit.cli.ceiling_calibrate import add_calibrate_parser
from posekit.errors import CalibrationError
from tests.ceiling.cli_harness import look_at, run_verb

DIST = (-0.2, 0.04, 0.0008, -0.0006, 0.0)
SIZE = (864, 480)


def pose(C=(3000.0, 300.0, -2300.0), target=(3000.0, 1800.0, 0.0)):
    return look_at(C, target)


def grid_points(dist, f=420.0, noise_px=0.0, rng=0):
    """Grid corners of a 6 m × 4 m ceiling (600 × 1200 mm tiles) seen by a camera with ``dist``:
    world (N, 2) mm, pixels (N, 2) as seen, and the lens."""
    lens = CameraModel.ideal(*SIZE, focal_px=f, dist=dist)
    R, t = pose()
    X, Y = np.meshgrid(np.arange(0, 6001, 600.0), np.arange(0, 4001, 1200.0))
    world = np.column_stack([X.ravel(), Y.ravel()])
    uv, _ = cv2.projectPoints(np.column_stack([world, np.zeros(len(world))]), cv2.Rodrigues(R)[0], t, lens.K,
                              lens.dist)
    uv = uv.reshape(-1, 2)
    uv_pin = (lens.K @ (world @ R[:, :2].T + t).T).T
    uv_pin = uv_pin[:, :2] / uv_pin[:, 2:]
    inside = np.all((uv > 5) & (uv < np.array(SIZE) - 6), axis=1) & np.all((uv_pin > -200), axis=1)
    uv = uv + np.random.default_rng(rng).normal(0, noise_px, uv.shape)
    return world[inside], uv[inside], lens


def test_radial_pattern_detected_on_a_distorting_lens():
    world, uv, _ = grid_points(DIST)
    assert len(world) >= 25
    rp = radial_pattern(world, uv)
    assert rp.detected and rp.t_stat > 6 and rp.explained > 0.6


@pytest.mark.parametrize("seed", range(10))
def test_no_false_alarm_on_a_pinhole_camera(seed):
    """Clicking noise (0.5 px) and two mis-clicks (20 px) on a distortion-free camera: no verdict."""
    world, uv, _ = grid_points((0, 0, 0, 0, 0), noise_px=0.5, rng=seed)
    uv = uv.copy()
    uv[3] += (20.0, 0.0)
    uv[11] += (0.0, -20.0)
    assert not radial_pattern(world, uv).detected


def test_undistorted_points_keep_every_point():
    world, uv, lens = grid_points(DIST, noise_px=0.2)
    cal = calibrate(world, undistort_calibration_points(lens, uv))
    assert cal.inliers.all()
    assert cal.rms_px < 0.35
    plain = calibrate(world, uv)
    assert plain.inliers.sum() < 0.7 * len(world)              # what happens without the lens model


run = partial(run_verb, add_calibrate_parser)


def write_points(path, world, uv):
    path.write_text("X,Y,u,v\n" + "".join(f"{X:g},{Y:g},{u:.4f},{v:.4f}\n" for (X, Y), (u, v) in zip(world, uv)))


def test_cli_says_lens_distortion_and_why_points_were_rejected(tmp_path, capsys):
    world, uv, lens = grid_points(DIST)
    pts = tmp_path / "pts.csv"
    write_points(pts, world, uv)
    assert run(["calibrate", str(pts), "--out", str(tmp_path / "cal.json")]) == 0
    cap = capsys.readouterr()
    assert "posekit: warning: looks like lens distortion: calibrate the camera (posekit ceiling camera) and " \
           "pass --camera" in cap.err
    n = len(world)
    line = [ln for ln in cap.out.splitlines() if ln.startswith("RANSAC rejected")][0]
    rejected = int(line.split()[2])
    assert rejected > n / 3
    assert line.endswith(f"{rejected} follow the radial pattern of lens distortion (not mis-clicks: use --camera)")
    assert sum(": X=" in ln and " mm" in ln for ln in cap.out.splitlines()) == n    # one residual line per point


def test_cli_with_camera_keeps_all_and_finds_the_misclicks(tmp_path, capsys):
    world, uv, lens = grid_points(DIST, noise_px=0.2)
    uv = uv.copy()
    uv[4] += (15.0, 0.0)
    uv[9] += (0.0, 12.0)
    pts, cam = tmp_path / "pts.csv", tmp_path / "cam.json"
    write_points(pts, world, uv)
    save_camera(lens, cam)
    assert run(["calibrate", str(pts), "--out", str(tmp_path / "cal.json"), "--camera", str(cam)]) == 0
    cap = capsys.readouterr()
    n = len(world)
    assert f"calibrated from {n - 2} of {n} points" in cap.out
    assert f"RANSAC rejected 2 of {n} points (more than 3 px from the fit of the others): 2 are off the fit alone " \
           "(mis-clicked or wrong X, Y?)" in cap.out
    tagged = [ln for ln in cap.out.splitlines() if ln.endswith("rejected")]
    assert [ln.split(":")[0].strip() for ln in tagged] == ["line 6", "line 11"]
    assert "looks like lens distortion" not in cap.err
    import json
    data = json.loads((tmp_path / "cal.json").read_text())
    assert data["undistorted"] is True
    assert_allclose(data["camera"]["dist"], DIST)
    from posekit.ceiling.camera.homography import load_calibration
    assert_allclose(load_calibration(tmp_path / "cal.json").camera.dist, DIST)   # read back with the file


def test_cli_point_outside_the_camera_image(tmp_path):
    world, uv, lens = grid_points(DIST)
    uv = uv.copy()
    uv[0] = (900.0, 10.0)
    pts, cam = tmp_path / "pts.csv", tmp_path / "cam.json"
    write_points(pts, world, uv)
    save_camera(lens, cam)
    with pytest.raises(CalibrationError) as exc:
        run(["calibrate", str(pts), "--out", str(tmp_path / "cal.json"), "--camera", str(cam)])
    assert str(exc.value) == ("line 2: u=900 v=10 is outside the 864x480 image of the --camera file; "
                              "expected pixels of that camera")


def test_cli_from_image_through_the_lens(tmp_path, capsys):
    """--from-image with --camera: the distorted reference image is undistorted before the grid
    finder; every crossing found lies on the lens's projection of its world point (truth of the
    renderer's calibration points, which are OpenCV-checked in test_render_realistic)."""
    from posekit.ceiling.camera.homography import load_calibration
    from posekit.ceiling.camera.points import read_points_csv
    from posekit.ceiling.sim.config import SceneConfig
    from posekit.ceiling.sim.video import render_video

    cfg = SceneConfig(dist=DIST, duration_s=0.2, width_px=432, height_px=240, focal_px=185.0)
    paths = render_video(cfg, tmp_path / "sim")
    pts = read_points_csv(paths.calibration_points)
    uv = pts.image_uv
    k = np.unique([np.argmin(uv.sum(1)), np.argmax(uv.sum(1)), np.argmin(uv[:, 0] - uv[:, 1]),
                   np.argmax(uv[:, 0] - uv[:, 1])])
    write_points(tmp_path / "seeds.csv", pts.world_xy[k], np.round(uv[k]))
    found = tmp_path / "found.csv"
    assert run(["calibrate", str(tmp_path / "seeds.csv"), "--from-image", str(paths.reference), "--camera",
                str(paths.camera), "--grid", "1200,600", "--out", str(tmp_path / "cal.json"),
                "--write-points", str(found), "--residuals", "none"]) == 0
    out = capsys.readouterr().out
    assert "(undistorted with --camera)" in out
    got = read_points_csv(found)
    truth = {tuple(w): p for w, p in zip(pts.world_xy, pts.image_uv)}
    d = [np.hypot(*(p - truth[tuple(w)])) for w, p in zip(got.world_xy, got.image_uv) if tuple(w) in truth]
    assert len(d) >= 15 and max(d) < 0.5                          # px, as seen through the lens
    cal = load_calibration(tmp_path / "cal.json")
    assert cal.rms_px < 0.2 and cal.inliers.all()
