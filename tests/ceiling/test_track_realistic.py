"""The tracker on the realistic renderer's video (``SceneConfig.realistic``: k1 = -0.2 lens,
blooming dot, auto-exposure steps, mp4v compression, a person and shadows crossing, a steady
and a blinking red LED, specular reflections): never ``ok`` off the dot, honest ``std_mm``.
The homography is the renderer's true one on undistorted pixels and the lens its own model, so
what is measured is detection and tracking (calibration is tested elsewhere)."""

import json

import numpy as np
import pytest

render = pytest.importorskip("posekit.ceiling.sim")


@pytest.fixture(scope="module")
def realistic(tmp_path_factory):
    if not hasattr(render.SceneConfig, "realistic"):
        pytest.skip("the realistic renderer is not there")
    out = tmp_path_factory.mktemp("realistic")
    cfg = render.SceneConfig.realistic(duration_s=16.0, seed=1)
    paths = render.render_video(cfg, out)
    scene = render.CeilingScene(cfg)
    H = scene.H_image_world
    (out / "cal.json").write_text(json.dumps({"H_image_world": H.tolist(), "H_world_image": np.linalg.inv(H).tolist(),
                                              "rms_px": 0.1, "rms_world": 1.0}))
    return out, paths, scene.truth()


def test_realistic_video_never_ok_off_the_dot_and_honest_std(realistic):
    from posekit.ceiling.track.pipeline import track_video
    out, paths, truth = realistic
    res = track_video(paths.video, out / "cal.json", camera=paths.camera)
    n = min(len(res), len(truth.frame))
    st, xy = res.status()[:n], res.xy()[:n]
    ok, vis = st == "ok", truth.visible[:n, 0]
    err = np.hypot(*(xy - truth.xy_red[:n]).T)
    std = np.array([r.std_mm for r in res.rows[:n]])
    assert np.count_nonzero(ok & ~vis) == 0                         # never ok without the dot
    assert np.count_nonzero(ok & (err > 20.0)) <= 0.01 * np.count_nonzero(ok)
    assert np.mean(err[ok] <= 2.5 * std[ok]) >= 0.9                 # std_mm honest
    assert np.median(err[ok]) < 3.0
    assert np.count_nonzero(ok) >= 0.7 * np.count_nonzero(vis)


def test_cli_track_with_the_camera_model(capsys, realistic, tmp_path):
    from posekit.ceiling.track.pipeline import read_track_csv
    from tests.cli_helpers import assert_one_line_error, run_cli
    out, paths, truth = realistic
    rc, stdout, err = run_cli(capsys, "ceiling", "track", paths.video, "--calibration", out / "cal.json", "--camera",
                              paths.camera, "--out", tmp_path / "t.csv")
    assert rc == 0, err
    t = read_track_csv(tmp_path / "t.csv")
    n = min(len(t["frame"]), len(truth.frame))
    ok = t["status"][:n] == "ok"
    err_mm = np.hypot(t["x"][:n] - truth.xy_red[:n, 0], t["y"][:n] - truth.xy_red[:n, 1])
    assert np.count_nonzero(ok) >= 0.7 * np.count_nonzero(truth.visible[:n, 0])
    assert np.median(err_mm[ok]) < 3.0 and np.mean(err_mm[ok] <= 2.5 * t["std_mm"][:n][ok]) >= 0.9
    # without the lens model the same video is tens of mm off at the edges
    rc, stdout, err = run_cli(capsys, "ceiling", "track", paths.video, "--calibration", out / "cal.json",
                              "--out", tmp_path / "t0.csv")
    t0 = read_track_csv(tmp_path / "t0.csv")
    ok0 = t0["status"][:n] == "ok"
    err0 = np.hypot(t0["x"][:n] - truth.xy_red[:n, 0], t0["y"][:n] - truth.xy_red[:n, 1])
    assert np.percentile(err0[ok0], 95) > 3 * np.percentile(err_mm[ok], 95)
    # a camera model for another resolution is refused in one line
    bad = tmp_path / "cam.json"
    cam = json.loads(paths.camera.read_text())
    cam["image_size"] = [640, 480]
    bad.write_text(json.dumps(cam))
    assert_one_line_error(*run_cli(capsys, "ceiling", "track", paths.video, "--calibration", out / "cal.json",
                                   "--camera", bad, "--out", tmp_path / "t1.csv"),
                          "frames are 864x480 px but the camera model is for 640x480 px")
