"""Laser dot detection (posekit.ceiling.detect.dots) on rendered ceiling frames."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from posekit.ceiling.detect.dots import DotDetector
from posekit.ceiling.detect.lines import LineDetector
from posekit.ceiling.detect.spots import LASER_COLORS, Dot
from posekit.ceiling.sim.config import SceneConfig
from posekit.ceiling.sim.render import CeilingScene
from posekit.ceiling.sim.scene_geometry import robot_path
from posekit.errors import ConfigError, InputFileError

CLEAN = dict(noise_std=0.0, drift_gain=0.0, drift_offset=0.0, gradient=0.0)
N_FRAMES = 45          # 3 s at 15 fps on the first side of the rectangle


def _errors(config, colors=("red",), predicted=False, n=N_FRAMES):
    """Run a detector over the first n frames; per colour, the errors (px) where the truth sees
    the dot, the number of frames it was missed, and dots reported where the truth has none."""
    scene = CeilingScene(config)
    truth = scene.truth()
    det = DotDetector(colors)
    errors = {c: [] for c in colors}
    missed = extra = 0
    for k, frame in enumerate(scene.frames(0, n)):
        uv = {"red": truth.uv_red[k], "green": truth.uv_green[k]}
        vis = {"red": truth.visible[k, 0], "green": truth.visible[k, 1]}
        dots = det.detect(frame, {c: uv[c] for c in colors} if predicted else None)
        for c in colors:
            mine = [d for d in dots if d.color == c]
            if vis[c] and mine:
                errors[c].append(np.hypot(mine[0].u - uv[c][0], mine[0].v - uv[c][1]))
            missed += vis[c] and not mine
            extra += max(len(mine) - int(vis[c]), 0)
    return {c: np.array(e) for c, e in errors.items()}, missed, extra


def test_subpixel_accuracy_noiseless():
    errors, missed, extra = _errors(SceneConfig(dots=("red",), **CLEAN))
    assert missed == 0 and extra == 0
    assert len(errors["red"]) > 30
    assert errors["red"].mean() < 0.2


def test_subpixel_accuracy_noisy_with_drift():
    errors, missed, extra = _errors(SceneConfig(dots=("red",), noise_std=3.0, drift_gain=0.15, drift_period_s=30.0,
                                                gradient=0.1, gradient_period_s=20.0, seed=11))
    assert missed == 0 and extra == 0
    assert errors["red"].mean() < 0.5


def test_two_colours_told_apart():
    errors, missed, extra = _errors(SceneConfig(dots=("red", "green"), seed=2), colors=("red", "green"))
    assert missed == 0 and extra == 0
    assert len(errors["red"]) > 20 and len(errors["green"]) > 10
    assert errors["red"].max() < 1.0 and errors["green"].max() < 1.0       # 40 cm ≈ 60 px apart


def test_two_red_dots_are_two_dots():
    scene = CeilingScene(SceneConfig(dots=("red", "red"), **CLEAN))
    truth = scene.truth()
    dots = DotDetector(("red",), background=scene.reference_image()).detect(scene.render_frame(0))
    assert [d.color for d in dots] == ["red", "red"]
    found = np.array(sorted((d.u, d.v) for d in dots))
    expected = np.array(sorted(map(tuple, (truth.uv_red[0], truth.uv_green[0]))))
    assert_allclose(found, expected, atol=0.2)


def test_colour_not_asked_for_is_ignored():
    scene = CeilingScene(SceneConfig(dots=("red", "green"), **CLEAN))
    dots = DotDetector(("green",), background=scene.reference_image()).detect(scene.render_frame(0))
    assert [d.color for d in dots] == ["green"]
    assert_allclose([dots[0].u, dots[0].v], scene.truth().uv_green[0], atol=0.2)


def test_no_false_dot_without_laser_under_drift():
    config = SceneConfig(dots=("red", "green"), laser_gain=0.0, drift_gain=0.2, drift_period_s=30.0,
                         drift_offset=6.0, gradient=0.1, gradient_period_s=20.0, duration_s=6.0, seed=4)
    # no laser, the illumination drifting: no candidate that could start a track (a saturated
    # core); the running variance lets a few faint blobs through at its 4σ bar (measured: 1 of
    # 90 frames, unsaturated), which only a verified, moving, saturated candidate could follow
    det = DotDetector(("red", "green"))
    faint = 0
    for frame in CeilingScene(config).frames():
        dots = det.detect(frame)
        assert not any(d.saturated for d in dots)
        faint += len(dots)
    assert faint <= 3 and det.rebuilds == 0


def test_roi_path_gives_the_full_frame_result():
    scene = CeilingScene(SceneConfig(dots=("red", "green"), seed=5))
    truth = scene.truth()
    for k in (0, 75, 85):
        frame = scene.render_frame(k)
        full = DotDetector(("red", "green")).detect(frame)
        pred = {"red": truth.uv_red[k] + [3.0, -2.0], "green": truth.uv_green[k] + [-4.0, 1.5]}
        roi = DotDetector(("red", "green"), roi_fallback=False).detect(frame, pred)
        assert len(full) == 2 and roi == full


def test_roi_falls_back_to_the_full_frame_on_a_wrong_prediction():
    scene = CeilingScene(SceneConfig(dots=("red",), **CLEAN))
    frame = scene.render_frame(0)
    far = scene.truth().uv_red[0] + [200.0, 100.0]
    assert DotDetector(roi_fallback=False).detect(frame, far) == []
    dots = DotDetector().detect(frame, far)
    assert len(dots) == 1 and dots == DotDetector().detect(frame)


def test_dot_in_a_vent_is_not_detected():
    config = SceneConfig(dots=("red",))
    scene = CeilingScene(config)
    truth = scene.truth()
    det = DotDetector()
    hidden = 0
    for k, frame in enumerate(scene.frames(0, 70)):      # the dot crosses a vent in frames 35-65
        dots = det.detect(frame)
        if not truth.visible[k, 0]:
            hidden += 1
            assert dots == []
    assert hidden > 10                           # the first side crosses a vent


def test_first_frame_without_a_reference():
    """The background is built from the first frame itself (laser pixels filled from their
    neighbourhood): the dot of a robot standing still is found at once, to a few tenths of a px."""
    scene = CeilingScene(SceneConfig(dots=("red",), **CLEAN))
    (dot,) = DotDetector().detect(scene.render_frame(0))
    assert_allclose([dot.u, dot.v], scene.truth().uv_red[0], atol=0.5)


def test_reference_background_and_reset():
    scene = CeilingScene(SceneConfig(dots=("red",), **CLEAN))
    frame = scene.render_frame(3)
    det = DotDetector(background=scene.reference_image())
    (dot,) = det.detect(frame)
    assert det.status == "started"
    assert_allclose([dot.u, dot.v], scene.truth().uv_red[3], atol=0.2)
    assert isinstance(dot, Dot) and dot.area_px >= 8 and dot.peak > 100
    det.detect(scene.render_frame(4))
    assert det.status == "ok"
    det.reset()
    assert det.background is None
    det.detect(frame)
    assert det.status == "started"


def test_light_switched_on_relights_the_background():
    """An exposure step (+40 grey levels everywhere) is a gain on the background, not a rebuild:
    the dot is found in the very frame; a scene that changed (another picture) is rebuilt, and
    both are counted."""
    scene = CeilingScene(SceneConfig(dots=("red",), **CLEAN))
    det = DotDetector()
    for k in range(5):
        det.detect(scene.render_frame(k))
    for k in (5, 6):
        brighter = np.clip(scene.render_frame(k).astype(int) + 40, 0, 255).astype(np.uint8)
        (dot,) = det.detect(brighter)
        assert det.status == ("relit" if k == 5 else "ok")
        assert_allclose([dot.u, dot.v], scene.truth().uv_red[k], atol=0.2)
    assert (det.relights, det.rebuilds) == (1, 0)
    other = np.random.default_rng(0).integers(0, 256, brighter.shape, dtype=np.uint8)
    det.detect(other)
    assert det.status == "rebuilt" and det.rebuilds == 1


def test_line_segment_case_c():
    config = SceneConfig(dots=("line",), **CLEAN)
    scene = CeilingScene(config)
    det, dots = LineDetector(background=scene.reference_image()), DotDetector(background=scene.reference_image())
    for k in (0, 20, 270):                     # along +X, then along +Y after the first turn
        frame = scene.render_frame(k)
        xy, heading = robot_path(config, [k / config.fps])
        d = 0.5 * config.line_length_mm * np.array([np.cos(heading[0]), np.sin(heading[0])])
        ends = scene.project(np.stack([xy[0] - d, xy[0] + d]))
        (line,) = det.detect(frame)
        expected = np.degrees(np.arctan2(*(ends[1] - ends[0])[::-1])) % 180.0
        assert abs((line.angle_deg - expected + 90.0) % 180.0 - 90.0) < 0.5
        assert_allclose([line.u, line.v], ends.mean(axis=0), atol=0.5)
        assert abs(line.length_px - np.linalg.norm(ends[1] - ends[0])) < 0.15 * line.length_px
        ends_found = line.endpoints()
        assert min(np.abs(ends_found - ends).max(), np.abs(ends_found[::-1] - ends).max()) < 0.15 * line.length_px
        assert dots.detect(frame) == []             # a segment is not a dot
    dot_frame = CeilingScene(SceneConfig(dots=("red",), **CLEAN)).render_frame(0)
    assert LineDetector(background=scene.reference_image()).detect(dot_frame) == []    # nor a dot a segment


def test_laser_colours_wrap_hue():
    red = LASER_COLORS["red"]
    assert list(red.hue_mask(np.array([0.0, 20.0, 345.0, 60.0, 200.0]))) == [True, True, True, False, False]


@pytest.mark.parametrize("kwargs, match", [
    (dict(colors=("blue",)), "colors: expected distinct names"),
    (dict(colors=("red", "red")), "colors: expected distinct names"),
    (dict(learning_rate=0.0), "learning_rate"),
    (dict(contrast=300), "contrast"),
    (dict(alpha_pixel=0.0), r"alpha_pixel: expected a probability in \(0, 0.5\), got 0.0"),
    (dict(relight_gain=0.0), r"relight_gain must be in \(0, 1\)"),
    (dict(block_px=0), r"block_px >= 1"),
])
def test_bad_parameters(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        DotDetector(**kwargs)


def test_bad_frames():
    det = DotDetector()
    with pytest.raises(InputFileError, match="expected a uint8 BGR image"):
        det.detect(np.zeros((48, 64), np.uint8))
    with pytest.raises(InputFileError, match="expected a uint8 BGR image"):
        det.detect(np.zeros((48, 64, 3), np.float32))
    det.detect(np.full((48, 64, 3), 120, np.uint8))
    with pytest.raises(InputFileError, match="expected 64×48 like the previous frames"):
        det.detect(np.full((40, 64, 3), 120, np.uint8))
    with pytest.raises(InputFileError, match="predicted_uv"):
        det.detect(np.full((48, 64, 3), 120, np.uint8), predicted_uv=(1.0, 2.0, 3.0))


def test_line_segment_case_c_by_hough_transform():
    """The Hough path (cv2.HoughLines on the bar's centre line) agrees with the truth."""
    config = SceneConfig(dots=("line",), **CLEAN)
    scene = CeilingScene(config)
    det = LineDetector(background=scene.reference_image(), method="hough")
    for k in (0, 20, 270, 400):
        xy, heading = robot_path(config, [k / config.fps])
        d = 0.5 * config.line_length_mm * np.array([np.cos(heading[0]), np.sin(heading[0])])
        ends = scene.project(np.stack([xy[0] - d, xy[0] + d]))
        (line,) = det.detect(scene.render_frame(k))
        expected = np.degrees(np.arctan2(*(ends[1] - ends[0])[::-1])) % 180.0
        assert abs((line.angle_deg - expected + 90.0) % 180.0 - 90.0) < 0.5
        assert_allclose([line.u, line.v], ends.mean(axis=0), atol=0.5)
        assert abs(line.length_px - np.linalg.norm(ends[1] - ends[0])) < 0.2 * line.length_px
    with pytest.raises(ConfigError, match="LineDetector: unknown method 'radon'; expected one of moments, hough"):
        LineDetector(method="radon")


def test_jpeg_compressed_dot_keeps_its_colour():
    """4:2:0 chroma of JPEG / MJPG / H.264 washes a small saturated dot's red halo out pixel by
    pixel (the independent generator's dot: white core, red rim): the colour of the light it
    adds, summed over the spot, keeps it at quality 50-90 in every frame, the first included
    (the first background replaces small saturated spots by their neighbourhood's median),
    its colour known; a white lamp of the same size is at most a spot of unknown colour (it
    can never start a track)."""
    import cv2

    from tests.ceiling.test_track_scene import Scene
    for q in (90, 75, 50):
        sc = Scene(n=40, seed=0)
        det = DotDetector(("red",))
        found = 0
        for k, _, frame in sc.frames():
            img = frame.copy()
            cv2.circle(img, (400, 200), 2, (255, 255, 255), -1)      # a white lamp
            img = cv2.imdecode(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, q])[1], cv2.IMREAD_COLOR)
            dots = det.detect(img)
            assert all(not d.colour_known for d in dots if np.hypot(d.u - 400, d.v - 200) <= 10)
            uv = sc.uv(sc.truth[k])[0]
            found += any(np.hypot(d.u - uv[0], d.v - uv[1]) < 0.5 and d.colour_known for d in dots)
        assert found == 40, q
