"""The realistic ceiling renderer: lens distortion, bloom, exposure steps, occluders, shadows, stray
lights, compression, checked against OpenCV's projection and against measurements of the pixels."""

import csv
import json
from dataclasses import replace
from functools import partial

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose

from posekit.ceiling.camera.lens import load_camera
from posekit.ceiling.sim.config import REALISTIC, SceneConfig
from posekit.ceiling.sim.render import CeilingScene
from posekit.ceiling.sim.scene_geometry import _camera as scene_camera
from posekit.ceiling.sim.scene_geometry import lens_camera, true_homography
from posekit.ceiling.sim.video import render_video
from posekit.cli.ceiling_simulate import add_simulate_parser
from posekit.errors import ConfigError
from tests.ceiling.cli_harness import run_verb

LENS = REALISTIC["dist"]
#: The default scene at half resolution (same view, quarter of the pixels: faster tests).
SMALL = dict(width_px=432, height_px=240, focal_px=185.0)


def opencv_project(config, xy):
    """World points (N, 2) mm on the ceiling through cv2.projectPoints with the scene's pose and lens."""
    K, R, t = scene_camera(config)
    rvec, _ = cv2.Rodrigues(R)
    uv, _ = cv2.projectPoints(np.column_stack([xy, np.zeros(len(xy))]), rvec, t, K, np.asarray(config.dist))
    return uv.reshape(-1, 2)


def test_projection_matches_opencv():
    cfg = SceneConfig(dist=LENS, duration_s=1.0, **SMALL)
    scene = CeilingScene(cfg)
    pts = scene.calibration_points(margin_px=5.0)
    assert len(pts) >= 25
    assert_allclose(pts[:, 2:], opencv_project(cfg, pts[:, :2]), atol=1e-6)
    # the homography maps undistorted pixels: undistorting the lens's pixels gives H·X
    lens = lens_camera(cfg)
    Hx = true_homography(cfg) @ np.column_stack([pts[:, :2], np.ones(len(pts))]).T
    assert_allclose(lens.undistort_points(pts[:, 2:]), (Hx[:2] / Hx[2]).T, atol=1e-4)


def test_distorted_dot_is_where_the_truth_says():
    """The centroid of the rendered dot (measured in the pixels) sits at the distorted truth."""
    cfg = SceneConfig(dist=LENS, duration_s=2.0, noise_std=0.0, motion_blur=False, holes=False, drift_gain=0.0,
                      drift_offset=0.0, gradient=0.0, **SMALL)
    scene = CeilingScene(cfg)
    truth = scene.truth()
    bg = scene.reference_image().astype(float)
    for k in (0, 20):
        diff = scene.render_frame(k).astype(float)[..., 2] - bg[..., 2]
        u0, v0 = np.round(truth.uv_red[k]).astype(int)
        win = np.clip(diff[v0 - 8:v0 + 9, u0 - 8:u0 + 9], 0, None)
        vv, uu = np.mgrid[v0 - 8:v0 + 9, u0 - 8:u0 + 9]
        c = np.array([(uu * win).sum(), (vv * win).sum()]) / win.sum()
        assert np.hypot(*(c - truth.uv_red[k])) < 0.15
        assert np.hypot(*(c - opencv_project(cfg, truth.xy_red[k:k + 1])[0])) < 0.15


def test_bloom_white_core_coloured_rim():
    cfg = SceneConfig(bloom=1.0, duration_s=1.0, noise_std=0.0, holes=False)
    scene = CeilingScene(cfg)
    f = scene.render_frame(0).astype(int)
    u, v = np.round(scene.truth().uv_red[0]).astype(int)
    assert (f[v, u] == 255).all()                                   # saturated white core
    core = (f[v - 6:v + 7, u - 6:u + 7] == 255).all(axis=2).sum()
    plain = (CeilingScene(replace(cfg, bloom=0.0)).render_frame(0)[v - 6:v + 7, u - 6:u + 7] == 255).all(axis=2).sum()
    assert core > plain                                             # the saturated disc is wider
    rim = f[v, u + 5]
    ref = scene.reference_image()[v, u + 5].astype(int)
    assert rim[2] - ref[2] > 20 and rim[2] - ref[2] > 3 * max(rim[1] - ref[1], 1)   # red rim


def test_exposure_steps_scale_the_frame():
    cfg = SceneConfig(exposure_step_s=2.0, duration_s=12.0, noise_std=0.0, drift_gain=0.0, drift_offset=0.0,
                      gradient=0.0, dots=("red",), **SMALL)
    scene = CeilingScene(cfg)
    times, levels = scene._exposure
    assert len(levels) > 4 and np.all(np.abs(levels[1:] - 1) >= 0.4 * 0.3 - 1e-9)
    k1 = int(np.ceil(times[1] * cfg.fps)) + 1                       # a frame after the first step
    a, b = scene.render_frame(0).astype(float), scene.render_frame(k1).astype(float)
    mask = (a > 30) & (a < 200) & (b < 250)
    ratio = np.median(b[mask] / a[mask])
    assert ratio == pytest.approx(scene.exposure(k1 / cfg.fps), rel=0.02)


def test_occluder_hides_the_dot_in_the_truth():
    for seed in range(10):                                          # the first seed where someone crosses the dot
        cfg = SceneConfig(occluders=2, duration_s=30.0, dots=("red",), holes=False, occluder_period_s=10.0,
                          seed=seed, **SMALL)
        scene = CeilingScene(cfg)
        truth = scene.truth()
        hidden = [k for k in range(scene.n_frames) if scene.occluded(truth.time_s[k], truth.uv_red[k])]
        if hidden:
            break
    assert hidden, "nobody crossed the dot in 10 seeds × 30 s"
    assert not truth.visible[hidden, 0].any()
    k = hidden[len(hidden) // 2]
    u, v = np.round(truth.uv_red[k]).astype(int)
    px = scene.render_frame(k)[v, u].astype(int)
    assert px.max() < 90                                            # dark person, no laser dot


def test_stray_lights_are_where_the_file_says(tmp_path):
    cfg = SceneConfig(stray_lights=1, blinking_lights=1, reflections=1, duration_s=2.0, noise_std=0.0, **SMALL)
    render_video(cfg, tmp_path)
    with open(tmp_path / "stray_lights.csv", newline="") as fh:
        lights = list(csv.DictReader(fh))
    assert [r["kind"] for r in lights] == ["steady", "blinking", "reflection"]
    scene = CeilingScene(cfg)
    ref = scene.reference_image().astype(int)
    on = {"steady": 0, "blinking": 0, "reflection": 0}
    for k in range(30):
        f = scene.render_frame(k).astype(int)
        for r in lights:
            u, v = round(float(r["u"])), round(float(r["v"]))
            on[r["kind"]] += int(f[v, u, 2] - ref[v, u, 2] > 60)
    assert on["steady"] == 30 and on["reflection"] == 30
    blink = lights[1]
    period, phase = float(blink["period_s"]), float(blink["phase_s"])
    expected = sum(((k / cfg.fps - phase) % period) < 0.5 * period for k in range(30))
    assert on["blinking"] == expected and 10 <= expected <= 20        # 1 s period, half on, 2 s of video
    path_xy = scene.truth().xy_red
    for r in lights:                                                 # never on the laser's path
        assert np.min(np.hypot(path_xy[:, 0] - float(r["x"]), path_xy[:, 1] - float(r["y"]))) >= 250


def test_mp4v_video_and_camera_file(tmp_path):
    cfg = SceneConfig(codec="mp4v", dist=LENS, duration_s=1.0, **SMALL)
    paths = render_video(cfg, tmp_path)
    assert paths.video.name == "video.mp4"
    cap = cv2.VideoCapture(str(paths.video))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == cfg.n_frames
    cam = load_camera(paths.camera)
    assert_allclose(cam.dist, LENS)
    assert cam.image_size == (432, 240) and cam.K[0, 0] == cfg.focal_px


run_sim = partial(run_verb, add_simulate_parser)


def test_cli_realistic_and_overrides(tmp_path, capsys):
    out = tmp_path / "sim"
    assert run_sim(["simulate", "--out", str(out), "--realistic", "--duration-s", "0.5", "--stray-lights", "0",
                    "--codec", "mjpg"]) == 0
    text = capsys.readouterr().out
    assert "effects: distortion k1=-0.2, bloom 1, exposure steps every ~8 s, 1 occluder(s), 2 shadow(s), " \
           "0 steady + 1 blinking red light(s), 2 reflection(s), codec mjpg" in text
    assert json.loads((out / "camera.json").read_text())["dist"] == list(LENS)
    assert (out / "video.avi").exists()


def test_cli_config_file(tmp_path, capsys):
    cfg = tmp_path / "scene.yaml"
    cfg.write_text("bloom: 0.5\nreflections: 1\n")
    assert run_sim(["simulate", "--out", str(tmp_path / "a"), "--config", str(cfg), "--duration-s", "0.2"]) == 0
    assert "bloom 0.5" in capsys.readouterr().out
    cfg.write_text("blooom: 1\n")
    with pytest.raises(ConfigError) as exc:
        run_sim(["simulate", "--out", str(tmp_path / "b"), "--config", str(cfg), "--duration-s", "0.2"])
    assert str(exc.value) == (f"{cfg}: unknown setting 'blooom'; expected keys of SceneConfig (e.g. dist, bloom, "
                              "occluders, stray_lights, codec, focal_px)")


@pytest.mark.parametrize("argv, message", [
    (["--distortion", "1,2"], "--distortion: expected 5 comma-separated numbers k1,k2,p1,p2,k3 within ±10, got '1,2'"),
    (["--codec", "h264"], "codec h264: OpenCV here cannot write avc1 video; expected one of mjpg, mp4v, xvid"),
])
def test_cli_bad_flags(tmp_path, argv, message):
    with pytest.raises(ConfigError) as exc:
        run_sim(["simulate", "--out", str(tmp_path / "x"), "--duration-s", "0.2", *argv])
    assert str(exc.value) == message


def test_config_errors():
    with pytest.raises(ConfigError, match=r"^codec: expected one of mjpg \| mp4v \| xvid \| h264, got 'avi'$"):
        SceneConfig(codec="avi")
    with pytest.raises(ConfigError, match=r"^occluders: expected a whole number 0..20, got 1.5$"):
        SceneConfig(occluders=1.5)


def test_stray_light_at_a_chosen_point():
    cfg = SceneConfig(stray_light_xy_mm=[(2200.0, 900.0)], duration_s=1.0, **SMALL)
    scene = CeilingScene(cfg)
    (light,) = scene.lights
    assert light.kind == "steady" and tuple(light.xy) == (2200.0, 900.0)
    assert_allclose(light.uv, opencv_project(cfg, np.array([[2200.0, 900.0]]))[0], atol=1e-6)
    with pytest.raises(ConfigError, match=r"^stray_light_xy_mm: expected a list of \(x, y\) points in mm"):
        SceneConfig(stray_light_xy_mm=[(1.0,)])
