"""Synthetic ceiling videos (posekit.ceiling.sim.render): determinism, geometry, truth, files, CLI."""

import csv
import math
from functools import partial

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from posekit.ceiling.sim.config import SceneConfig
from posekit.ceiling.sim.render import CeilingScene, iter_frames
from posekit.ceiling.sim.scene_geometry import robot_path, true_homography
from posekit.ceiling.sim.video import TRUTH_HEADER, render_video
from posekit.cli.ceiling_simulate import add_simulate_parser
from posekit.errors import ConfigError
from tests.ceiling.cli_harness import run_verb

#: A frame is the reference plus the dot sprites only: no drift, no noise.
CLEAN = dict(noise_std=0.0, drift_gain=0.0, drift_offset=0.0, gradient=0.0)


def _apply(H, xy):
    q = np.c_[xy, np.ones(len(xy))] @ H.T
    return q[:, :2] / q[:, 2:]


def _centroid(diff, uv, half=8):
    """Intensity-weighted centroid (u, v) of a background difference (H, W) around uv."""
    u0, v0 = int(round(uv[0])), int(round(uv[1]))
    win = np.maximum(diff[v0 - half:v0 + half + 1, u0 - half:u0 + half + 1] - 3.0, 0.0)
    vv, uu = np.mgrid[v0 - half:v0 + half + 1, u0 - half:u0 + half + 1]
    return np.array([(win * uu).sum(), (win * vv).sum()]) / win.sum()


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    config = SceneConfig(dots=("red", "green"), duration_s=1.0, seed=3)
    out = tmp_path_factory.mktemp("ceiling_video")
    return config, render_video(config, out, frames_png=True)


# --- determinism ------------------------------------------------------------------------------

def test_same_seed_same_frames_and_frames_render_alone():
    config = SceneConfig(dots=("red", "green"), duration_s=3.0, seed=7)
    a = list(iter_frames(config, 0, 3))
    b = CeilingScene(config)
    for k, frame in enumerate(a):
        assert frame.dtype == np.uint8 and frame.shape == (480, 864, 3)
        assert_array_equal(frame, b.render_frame(k))
    assert_array_equal(CeilingScene(config).render_frame(40), b.render_frame(40))   # random access


def test_other_seed_other_noise_other_ceiling_seed_other_tiles():
    a = CeilingScene(SceneConfig(seed=1)).render_frame(5)
    b = CeilingScene(SceneConfig(seed=2)).render_frame(5)
    assert np.count_nonzero(a != b) > a.size // 4
    ref = CeilingScene(SceneConfig(seed=1)).reference_image()
    assert np.array_equal(ref, CeilingScene(SceneConfig(seed=2)).reference_image())
    other = CeilingScene(SceneConfig(ceiling_seed=1)).reference_image()
    assert np.count_nonzero(ref != other) > ref.size // 4


# --- geometry and truth -----------------------------------------------------------------------

def test_homography_maps_calibration_points(video):
    config, paths = video
    with open(paths.calibration_points) as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["X", "Y", "u", "v"]
    pts = np.array([[float(r[k]) for k in "XYuv"] for r in rows])
    assert len(pts) >= 18
    H = true_homography(config)
    assert_allclose(_apply(H, pts[:, :2]), pts[:, 2:], atol=1e-3)
    # they are grid corners: multiples of the tile size, and T-bar crossings in the picture
    assert_allclose(np.mod(pts[:, :2], config.tile_size_mm), 0.0, atol=1e-6)
    ref = cv2.imread(str(paths.reference)).astype(float).sum(axis=2)
    u, v = np.rint(pts[:, 2]).astype(int), np.rint(pts[:, 3]).astype(int)
    tiles = np.max([ref[v + dv, u + du] for du in (-6, 6) for dv in (-6, 6)], axis=0)
    assert np.all(ref[v, u] < 0.9 * tiles)


def test_homography_is_the_pinhole_camera_on_the_ceiling_plane():
    from posekit.ceiling.sim.scene_geometry import _camera

    config = SceneConfig()
    K, R, t = _camera(config)
    assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert_allclose(-R.T @ t, config.camera_position_mm, atol=1e-9)
    XY = np.array([[0.0, 0.0], [1200.0, 600.0], [5200.0, 3200.0], [3000.0, 2000.0]])
    P = np.c_[XY, np.zeros(len(XY))]
    uv, _ = cv2.projectPoints(P, cv2.Rodrigues(R)[0], t, K, None)
    assert_allclose(_apply(true_homography(config), XY), uv[:, 0], atol=1e-6)


def test_robot_path_rectangle():
    config = SceneConfig()
    side = 4400.0 / config.speed_mm_s                # first side: (800, 800) -> (5200, 800)
    turn = 90.0 / config.turn_rate_deg_s
    xy, heading = robot_path(config, [0.0, side / 2, side, side + turn / 2, side + turn, side + turn + 1.0])
    assert_allclose(xy[:3], [[800, 800], [3000, 800], [5200, 800]], atol=1e-9)
    assert_allclose(xy[3:5], [[5200, 800], [5200, 800]], atol=1e-9)       # turns on the spot
    assert_allclose(xy[5], [5200, 800 + config.speed_mm_s], atol=1e-9)
    assert_allclose(np.degrees(heading), [0, 0, 0, 45, 90, 90], atol=1e-9)
    lap = 2 * (4400 + 2400) / config.speed_mm_s + 4 * turn
    xy_lap, h_lap = robot_path(config, [lap])
    assert_allclose(xy_lap[0], [800, 800], atol=1e-9)
    assert_allclose(h_lap[0], 2 * math.pi, atol=1e-12)


def test_truth_heading_and_spacing():
    config = SceneConfig(dots=("red", "green"), duration_s=60.0)
    truth = CeilingScene(config).truth()
    d = truth.xy_green - truth.xy_red
    assert_allclose(np.hypot(d[:, 0], d[:, 1]), 400.0, atol=1e-9)
    assert_allclose(np.arctan2(d[:, 1], d[:, 0]), truth.heading_rad, atol=1e-9)
    assert np.all((truth.heading_rad > -math.pi) & (truth.heading_rad <= math.pi))


def test_dot_appears_where_the_truth_says():
    """Noiseless, drift-free frames: the centroid of frame − reference is the projected laser
    position within 0.3 px wherever the dot lies on a plain tile (0.1 px on average)."""
    from posekit.ceiling.sim.render import _ceiling_albedo

    config = SceneConfig(dots=("red", "green"), duration_s=60.0, **CLEAN)
    scene = CeilingScene(config)
    truth = scene.truth()
    ref = scene.reference_image().astype(float)
    errors = []
    for k in range(0, config.n_frames, 23):
        diff = (scene.render_frame(k).astype(float) - ref).sum(axis=2)
        for i, (uv, xy) in enumerate(((truth.uv_red[k], truth.xy_red[k]), (truth.uv_green[k], truth.xy_green[k]))):
            _, _, face = _ceiling_albedo(config, xy[:1], xy[1:])
            if not truth.visible[k, i] or not face[0] or not (10 < uv[0] < 853 and 10 < uv[1] < 469):
                continue
            errors.append(np.hypot(*(_centroid(diff, uv) - uv)))
    assert len(errors) > 40
    assert max(errors) < 0.3
    assert np.mean(errors) < 0.1


def test_holes_hide_the_dot():
    config = SceneConfig(dots=("red",), duration_s=60.0, **CLEAN)
    dark = SceneConfig(dots=("red",), duration_s=60.0, laser_gain=0.0, **CLEAN)
    scene, empty = CeilingScene(config), CeilingScene(dark)
    truth = scene.truth()
    uv = truth.uv_red
    in_view = (uv[:, 0] > 0) & (uv[:, 0] < 863) & (uv[:, 1] > 0) & (uv[:, 1] < 479)
    hidden = np.flatnonzero(~truth.visible[:, 0] & in_view)
    assert len(hidden) > 20                          # the default path crosses vents
    for k in hidden[:: max(1, len(hidden) // 5)]:
        assert_array_equal(scene.render_frame(k), empty.render_frame(k))
    k = np.flatnonzero(truth.visible[:, 0])[10]
    assert np.count_nonzero(scene.render_frame(k) != empty.render_frame(k)) > 20
    no_holes = CeilingScene(SceneConfig(dots=("red",), duration_s=60.0, holes=False)).truth()
    assert no_holes.visible[hidden, 0].all()


# --- files ------------------------------------------------------------------------------------

def test_video_reads_back(video):
    config, paths = video
    cap = cv2.VideoCapture(str(paths.video))
    assert cap.isOpened()
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == config.n_frames == 15
    scene = CeilingScene(config)
    n = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        assert frame.shape == (480, 864, 3)
        assert np.abs(frame.astype(float) - scene.render_frame(n)).mean() < 4.0     # MJPG at quality 95
        n += 1
    cap.release()
    assert n == config.n_frames
    pngs = sorted(paths.frames_dir.glob("*.png"))
    assert len(pngs) == n
    assert_array_equal(cv2.imread(str(pngs[4])), scene.render_frame(4))             # lossless
    assert_array_equal(cv2.imread(str(paths.reference)), scene.reference_image())


def test_truth_csv(video):
    config, paths = video
    with open(paths.truth) as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == TRUTH_HEADER
    assert tuple(rows[0][:7]) == ("frame", "time_s", "x", "y", "heading_deg", "red_visible", "green_visible")
    assert len(rows) == 1 + config.n_frames
    truth = CeilingScene(config).truth()
    data = np.array([[float(v) for v in r[:9]] for r in rows[1:]])
    assert_array_equal(data[:, 0], np.arange(config.n_frames))
    assert_allclose(data[:, 2:4], truth.xy_red, atol=1e-3)
    assert_allclose(data[:, 7:9], truth.uv_red, atol=1e-4)
    assert set(data[:, 5]) <= {0.0, 1.0}


# --- configuration and CLI --------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, match", [
    (dict(dots=("blue",)), "dots: expected one of"),
    (dict(fps=0.0), "fps: expected a positive number"),
    (dict(camera_position_mm=(3000.0, 400.0, 100.0)), "below the ceiling"),
    (dict(path_rect_mm=(800.0, 800.0, 700.0, 3200.0)), "path_rect_mm"),
    (dict(hole_rects_mm=[[0.0, 0.0, 100.0]]), "hole_rects_mm: expected rectangles"),
])
def test_bad_config(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        SceneConfig(**kwargs)


def test_config_from_lists_is_hashable():
    config = SceneConfig(dots=["red", "green"], hole_rects_mm=[[0, 0, 100, 100]], path_rect_mm=[800, 800, 5200, 3200])
    assert config.dots == ("red", "green") and config.hole_rects_mm == ((0.0, 0.0, 100.0, 100.0),)
    assert hash(config) == hash(SceneConfig(dots=("red", "green"), hole_rects_mm=((0, 0, 100, 100),)))


_cli = partial(run_verb, add_simulate_parser)


def test_cli_simulate(tmp_path, capsys):
    out = tmp_path / "sim"
    assert _cli(["simulate", "--out", str(out), "--duration-s", "0.4", "--dots", "red,green", "--no-holes",
                 "--seed", "5"]) == 0
    assert "wrote 6 frames" in capsys.readouterr().out
    for name in ("video.avi", "truth.csv", "calibration_points.csv", "reference.png"):
        assert (out / name).is_file()
    assert not (out / "frames").exists()
    with open(out / "truth.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and rows[0]["green_visible"] in ("0", "1")
    with pytest.raises(ConfigError, match="--dots: expected one of"):
        _cli(["simulate", "--out", str(out), "--dots", "blue"])
