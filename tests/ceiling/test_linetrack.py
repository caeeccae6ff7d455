"""Case C: position and heading from one laser line, the 180° ambiguity resolved by the motion."""

import argparse

import numpy as np
import pytest

from posekit.ceiling.track.cameras import Camera
from posekit.ceiling.track.linetrack import (
    LineTracker,
    LineTrackerConfig,
    line_world_measurement,
    wrap_half,
)
from posekit.ceiling.track.pipeline import parse_dots, read_track_csv, track_frames
from posekit.ceiling.track.types import TrackerConfig
from posekit.errors import ConfigError

FPS = 15.0


def ends(xy, heading, length=300.0, swap=False):
    d = 0.5 * length * np.array([np.cos(heading), np.sin(heading)])
    e = np.stack([xy - d, xy + d])
    return e[::-1] if swap else e


def dh_deg(h_deg, truth_rad):
    return (np.asarray(h_deg) - np.degrees(truth_rad) + 180.0) % 360.0 - 180.0


# --- synthetic world measurements -------------------------------------------------------------

def test_line_measurement_and_half_wrap():
    mid, cov, phi, var, length = line_world_measurement([[0.0, 0.0], [-100.0, -100.0]])
    assert np.allclose(mid, [-50.0, -50.0]) and length == pytest.approx(np.hypot(100, 100))
    assert phi == pytest.approx(np.pi / 4)                       # mod 180°: the sense is lost
    assert var > 0 and np.allclose(cov, 0.5 * np.eye(2))
    assert wrap_half(np.radians(100.0)) == pytest.approx(np.radians(-80.0))
    assert parse_dots("line") == ("line",)
    with pytest.raises(ConfigError, match="'line,blue'"):
        parse_dots("line,blue")
    with pytest.raises(ConfigError):
        LineTrackerConfig(flip_after=0)


def test_heading_unknown_until_moved_then_continuous_through_90_and_180():
    """Spin on the spot first (sense unknown), then drive circles (heading sweeps every angle,
    the line's axis crosses ±90° and 0/180° many times); ends given in random order."""
    rng = np.random.default_rng(1)
    lt = LineTracker()
    rows, truth = [], []
    for k in range(15):                                  # turning on the spot: no motion cue
        h = np.radians(20.0) + 0.5 * k / FPS
        rows.append(lt.step(k / FPS, ends(np.array([1000.0, 1000.0]), h, swap=rng.random() < 0.5)))
        truth.append(h)
    assert all(np.isnan(r.heading_deg) for r in rows) and all(r.status == "ok" for r in rows)
    r_mm, w = 500.0, 0.4                                  # 200 mm/s on a 500 mm circle
    c = np.array([1000.0, 1000.0]) - r_mm * np.array([np.cos(h - np.pi / 2), np.sin(h - np.pi / 2)])
    a0 = h - np.pi / 2
    for k in range(15, 15 + 400):
        a = a0 + w * (k - 14) / FPS
        xy = c + r_mm * np.array([np.cos(a), np.sin(a)]) + rng.normal(0, 0.5, 2)
        hk = a + np.pi / 2
        rows.append(lt.step(k / FPS, ends(xy, hk + rng.normal(0, 0.002), swap=rng.random() < 0.5)))
        truth.append(hk)
    h = np.array([r.heading_deg for r in rows])
    first = int(np.argmax(np.isfinite(h)))
    assert 15 < first < 25                                # known within a few cm of driving
    assert np.all(np.isfinite(h[first:]))
    err = dh_deg(h[first:], np.array(truth[first:]))
    assert np.abs(err).max() < 1.5
    step = np.abs((np.diff(h[first:]) + 180.0) % 360.0 - 180.0)
    assert step.max() < 3.0                              # 0.4 rad/s is 1.5°/frame: no 180° jumps
    assert lt.n_flips == 0


def test_wrong_branch_flipped_when_driving_straight():
    lt = LineTracker(LineTrackerConfig(flip_after=5))
    heading = np.radians(-90.0)                           # axis exactly on the ±90° seam
    for k in range(10):
        lt.step(k / FPS, ends(np.array([500.0, 2000.0 - 20.0 * k]), heading))
    row = lt.step(10 / FPS, ends(np.array([500.0, 1800.0]), heading))
    assert abs(dh_deg(row.heading_deg, heading)) < 1.0
    lt.heading.x = lt.heading.x + np.array([np.pi, 0.0])  # as if the branch had been chosen wrongly
    out = [lt.step(k / FPS, ends(np.array([500.0, 2000.0 - 20.0 * k]), heading)) for k in range(11, 30)]
    err = np.abs(dh_deg([r.heading_deg for r in out], heading))
    assert np.all(err[-10:] < 1.0) and lt.n_flips == 1


def test_never_ok_without_a_line_and_heading_forgotten_when_lost():
    lt = LineTracker(LineTrackerConfig(tracker=TrackerConfig(max_predict_s=0.5)))
    rows = []
    for k in range(60):
        seen = not (20 <= k < 40)
        e = ends(np.array([1000.0 + 20.0 * k, 800.0]), 0.0) if seen else None
        rows.append(lt.step(k / FPS, e))
    st = np.array([r.status for r in rows])
    assert np.all(st[:20] == "ok") and np.all(st[40:] == "ok")
    assert np.all(st[20:27] == "predicted") and np.all(st[27:40] == "lost")   # 0.5 s = 7.5 frames
    h = np.array([r.heading_deg for r in rows])
    assert np.all(np.isfinite(h[5:27])) and np.all(np.isnan(h[27:41]))     # re-learnt from motion
    assert np.all(np.abs(h[45:]) < 1.0)


# --- rendered video (renderer + LineDetector + calibration) ----------------------------------

def scene_and_camera(cfg):
    render = pytest.importorskip("posekit.ceiling.sim")
    from posekit.ceiling.camera.homography import calibrate
    scene = render.CeilingScene(cfg)
    pts = scene.calibration_points()
    return scene, Camera(calibrate(pts[:, :2], pts[:, 2:]), (cfg.width_px, cfg.height_px))


class RecordingDetector:
    """LineDetector that records whether it found a segment in each frame."""

    def __init__(self):
        from posekit.ceiling.detect.lines import LineDetector
        self.det, self.found = LineDetector(), []
        self.colors = self.det.colors

    def detect(self, img, predicted_uv=None):
        lines = self.det.detect(img, predicted_uv=predicted_uv)
        self.found.append(bool(lines))
        return lines


@pytest.mark.parametrize("phase_s, seconds", [(12.0, 6.0), (0.0, 4.0)])
def test_rendered_line_clip(phase_s, seconds):
    """12 s: drive, stop, turn 90° on the spot, drive on; 0 s: the line crosses a vent."""
    render = pytest.importorskip("posekit.ceiling.sim")
    cfg = render.SceneConfig(dots=("line",), duration_s=seconds, path_phase_s=phase_s, noise_std=2.0)
    scene, cam = scene_and_camera(cfg)
    det = RecordingDetector()
    frames = ((k, k / cfg.fps, img) for k, img in enumerate(scene.frames()))
    res = track_frames(frames, [cam], ("line",), detectors=[det])
    truth = scene.truth()
    st, xy, h = res.status(), res.xy(), res.heading_deg()
    ok = st == "ok"
    assert not np.any(ok & ~np.array(det.found))           # never ok without a detected line
    assert ok.sum() >= truth.visible[:, 0].sum() - 1
    first = int(np.argmax(np.isfinite(h)))
    assert first <= 5                                     # 300 mm/s: 30 mm in a few frames
    sel = ok & (np.arange(len(st)) >= first)
    assert np.all(np.isfinite(h[sel]))
    err = np.abs(dh_deg(h[sel], truth.heading_rad[sel]))
    assert err.max() < 3.0                                # the branch is right: never 180° off
    e = np.hypot(*(xy[ok] - truth.xy_red[ok]).T)
    assert e.mean() < 3.0 and e.max() < 8.0


@pytest.mark.parametrize("method", ["moments", "hough"])
def test_cli_track_line(capsys, tmp_path, method):
    render = pytest.importorskip("posekit.ceiling.sim")
    from posekit.ceiling.camera.homography import calibrate
    from posekit.ceiling.camera.points import read_points_csv
    from posekit.ceiling.studies.truth import read_truth_csv
    from posekit.cli.ceiling_track import add_track_parser
    cfg = render.SceneConfig(dots=("line",), duration_s=2.0, path_phase_s=12.0)
    paths = render.render_video(cfg, tmp_path)
    p = read_points_csv(paths.calibration_points)
    calibrate(p.world_xy, p.image_uv).to_json(tmp_path / "cal.json")
    parser = argparse.ArgumentParser()
    add_track_parser(parser.add_subparsers(dest="verb"))
    out = tmp_path / "track.csv"
    args = parser.parse_args(["track", str(paths.video), "--calibration", str(tmp_path / "cal.json"),
                              "--dots", "line", "--line-method", method, "--out", str(out)])
    assert args.func(args) == 0
    assert "30 frames: 30 ok" in capsys.readouterr().out
    t, truth = read_track_csv(out), read_truth_csv(paths.truth)
    assert out.read_text().splitlines()[0] == "frame,time_s,x,y,heading_deg,status,std_mm,std_heading_deg,reason"
    known = np.isfinite(t["heading_deg"])
    assert known.sum() >= 25
    assert np.abs(dh_deg(t["heading_deg"][known], np.radians(truth.heading_deg[known]))).max() < 3.0
    assert np.hypot(t["x"] - truth.xy[:, 0], t["y"] - truth.xy[:, 1]).max() < 8.0


def test_cli_track_dotted_line(capsys, tmp_path):
    """§III-C: `track --dots line --line-method dotted` on the dotted line `simulate` renders; the
    solid-line measurement finds no segment in it (so the method must be chosen)."""
    render = pytest.importorskip("posekit.ceiling.sim")
    from posekit.ceiling.camera.homography import calibrate
    from posekit.ceiling.camera.points import read_points_csv
    from posekit.ceiling.studies.truth import read_truth_csv
    from posekit.cli.ceiling_track import add_track_parser
    cfg = render.SceneConfig(dots=("line",), duration_s=4.0, path_phase_s=12.0, line_pattern="dotted")
    paths = render.render_video(cfg, tmp_path)
    p = read_points_csv(paths.calibration_points)
    calibrate(p.world_xy, p.image_uv).to_json(tmp_path / "cal.json")
    parser = argparse.ArgumentParser()
    add_track_parser(parser.add_subparsers(dest="verb"))
    counts = {}
    for method in ("dotted", "moments"):
        out = tmp_path / f"track-{method}.csv"
        args = parser.parse_args(["track", str(paths.video), "--calibration", str(tmp_path / "cal.json"),
                                  "--dots", "line", "--line-method", method, "--out", str(out)])
        assert args.func(args) == 0
        capsys.readouterr()
        t = read_track_csv(out)
        counts[method] = int(np.sum(t["status"] == "ok"))
    truth = read_truth_csv(paths.truth)
    t = read_track_csv(tmp_path / "track-dotted.csv")
    ok = t["status"] == "ok"
    assert counts["dotted"] >= 50 and counts["moments"] == 0, counts
    err = np.hypot(t["x"][ok] - truth.xy[ok, 0], t["y"][ok] - truth.xy[ok, 1])
    assert err.mean() < 1.5 and err.max() < 5.0
