"""The ceiling tracker judged on real camera footage (OpenCV's ``vtest.avi``, people walking past
brick, grass, cones and a striped barrier tape; ``tests/data/ceiling/SOURCE.md``) with a laser dot
and red lamps drawn by the test's own generator (``footage.py``), never by the project's renderer.

Issue 25's bar, per scene: no dot → 0 ``ok``; dot → ≥ 90 % of the visible frames ``ok`` after
acquisition, median error ≤ 3 mm, ≥ 80 % of the ``ok`` errors within 2 × ``std_mm`` (2-D errors:
an honest 1σ gives 86.5 %), 0 ``ok`` rows more than 50 mm off, acquisition within 1 s of motion,
predicted rows within 3 × ``std_mm`` at least 90 % of the time. Figures measured at the time of
writing are in the comments (``docs/notes/issue-25.md`` has the command that prints them).
"""

import numpy as np
import pytest
from footage import FPS, Overlay, calibration, decoy_path, judge, robot_path, scenes

from posekit.ceiling.detect.dots import DotDetector
from posekit.ceiling.detect.scene import MOVING, STATIC, StaticLights
from posekit.ceiling.track.cameras import Camera
from posekit.ceiling.track.pipeline import track_frames

LAMPS = {"lamp_xy": (700.0, 600.0), "blink_xy": (1200.0, 300.0)}


def run(scene: Overlay, **detector):
    cam = Camera(calibration(clip=scene.clip), scene.size)
    dets = [DotDetector(("red",), **detector)] if detector else None
    return track_frames(scene.frames(), [cam], ("red",), detectors=dets)


def test_no_dot_is_never_ok():
    # real footage with a steady and a blinking red lamp drawn like the laser: measured 0 ok and 0
    # suspect of 300 (without the lamps too; before this round the same clip gave 0 ok only
    # because the detector was blind, and a steady lamp elsewhere gave 691 ok of 795)
    res = run(Overlay(dot=False, **LAMPS))
    assert res.counts()["ok"] == 0 and res.counts()["suspect"] == 0
    assert res.stats["rebuilds"] == 0                     # people, cars, compression: never a rebuild
    lost = [r for r in res.rows if r.status == "lost"]
    assert lost and all(r.reasons for r in lost)


@pytest.mark.parametrize("lamps", [False, True], ids=["plain", "steady+blinking lamp"])
def test_dot_on_real_footage_meets_the_bar(lamps):
    # measured: plain ok 0.900, median 0.42 mm, 2σ 0.860, 0 > 50 mm, acquired 0.2 s after the start
    # of motion, predicted 1.0 within 3σ; with the lamps 0.908, 0.46 mm, 0.865, 0, 0.3 s, 1.0
    scene = Overlay(**(LAMPS if lamps else {}))
    res = run(scene)
    j = judge(res.rows, scene)
    assert j["ok_far"] == 0 and j["ok_unseen"] == 0
    assert j["ok_rate"] >= 0.90
    assert j["median_mm"] <= 3.0
    assert j["cover_2s"] >= 0.80
    assert 0.0 <= j["acquired_s"] <= 1.0
    assert j["pred_cover_3s"] >= 0.90
    assert res.stats["rebuilds"] == 0 and res.stats["scene"] == "learned online"
    assert all(r.reasons == () for r in res.rows if r.status == "ok")


@pytest.mark.parametrize(("clip", "stride"), [("parking", 4), ("parking", 8), ("vtest", 8)])
def test_traffic_without_a_dot_is_never_ok_whatever_the_background_stride(clip, stride):
    # a parking lot seen from above (Intel's car-detection clip): red and white cars with tail
    # lights and glints drive through, plus a steady and a blinking red lamp drawn like the laser.
    # The tail lights move steadily and saturate: what rejects them is the ring test (they sit
    # on a car, not on the unchanged ceiling). Measured 0 ok, 0 suspect of 300 at strides 1, 2, 4
    # and 8 on both clips (round 1: 5 ok rows here, 102 on a traffic clip not in the tree; a
    # band of 1/8 of the rows per frame instead of 1/4 then turned 0 into 100)
    res = run(Overlay(dot=False, clip=clip, lamp_xy=(700.0, 600.0), blink_xy=(1200.0, 300.0)),
              background_stride=stride)
    assert res.counts()["ok"] == 0 and res.counts()["suspect"] == 0
    assert res.stats["rebuilds"] == 0


def test_dot_on_a_parking_lot_meets_the_bar():
    # measured: ok 0.941 of the visible frames, median 0.25 mm, 0.994 within 2σ, 0 > 50 mm,
    # acquired 0.32 s after the start of motion, predicted 1.0 within 3σ
    scene = scenes("parking")["dot"]
    res = run(scene)
    j = judge(res.rows, scene)
    assert j["ok_far"] == 0 and j["ok_unseen"] == 0 and j["ok_on_object"] == 0
    assert j["ok_rate"] >= 0.90 and j["median_mm"] <= 3.0 and j["cover_2s"] >= 0.80
    assert 0.0 <= j["acquired_s"] <= 1.0 and j["pred_cover_3s"] >= 0.90


def test_jpeg_quality_60_is_never_ok_off_the_dot():
    # quality 60 (and 60 twice): the dot merges with the striped barrier tape now and then.
    # Measured: ok 0.917 of the visible frames, 0 ok > 50 mm, 0.909 within 2σ (twice: 0.912, 0,
    # 0.909); round 1: 12 ok rows > 50 mm off with σ 3-8 mm
    scene = scenes("vtest")["dot, JPEG q60"]
    res = run(scene)
    j = judge(res.rows, scene)
    assert j["ok_far"] == 0 and j["ok_unseen"] == 0
    assert j["cover_2s"] >= 0.80 and j["ok_rate"] >= 0.80
    assert j["pred_cover_3s"] >= 0.90


@pytest.mark.parametrize("clip", ["vtest", "parking"])
def test_predicted_rows_are_honest_under_a_moving_decoy(clip):
    # the decoy runs 0.3-0.8 m away while the dot is hidden and after: the rows in doubt carry the
    # two hypotheses in their std_mm. Measured pred_cover_3s 1.0 on both (round 1: 0.69), 0 ok off
    # the dot; ok 0.884 (vtest) and 0.639 (parking) of the visible frames: while two moving
    # laser-like spots are in view the rows are suspect, by design
    scene = Overlay(decoy=decoy_path(clip), clip=clip)
    res = run(scene)
    j = judge(res.rows, scene)
    assert j["ok_far"] == 0 and j["ok_unseen"] == 0
    assert j["pred_cover_3s"] >= 0.90


def test_a_moving_decoy_while_the_dot_is_hidden_is_never_a_confident_jump():
    # a second laser-like spot moves 0.5-0.8 m away while the dot is occluded (0.8 s) and after:
    # the jump to it is suspect (probation, then "another moving spot"), never ok off the dot
    path = robot_path()
    decoy = np.full_like(path, np.nan)
    k = np.arange(140, 220)
    decoy[k] = np.c_[800.0 + 15.0 * (k - 140), np.full(len(k), 1150.0)]
    scene = Overlay(decoy=decoy)
    res = run(scene)
    j = judge(res.rows, scene)
    assert j["ok_far"] == 0 and j["ok_unseen"] == 0       # measured: 0 and 0 (ok 193 of 300)
    sus = [r for r in res.rows if r.status == "suspect"]
    assert sus and all("re-acquired" in r.reason or "another moving" in r.reason for r in sus)


def test_occluded_longer_than_max_predict_is_predicted_honestly_then_lost():
    # 1.6 s behind an occluder while driving 230 mm/s: predicted rows within 3σ, then lost, then
    # re-acquired within 1 s of reappearing (it moves)
    scene = Overlay(occluded=((146, 162),))
    res = run(scene)
    st = np.array([r.status for r in res.rows])
    assert st[150] == "predicted" and st[160] == "lost"
    j = judge(res.rows, scene)
    assert j["pred_cover_3s"] >= 0.90 and j["ok_far"] == 0
    back = np.flatnonzero(st[162:] == "ok")
    assert back.size and back[0] <= FPS


def test_static_light_test_false_motion_rate_is_alpha():
    # independent Gaussian jitter of a lamp, 20-sighting windows: the test calls it moving at
    # about alpha (1e-3); bound: 3 alpha + 4 binomial sd over 20,000 windows
    rng = np.random.default_rng(5)
    sl = StaticLights(alpha=1e-3, jitter_floor_px=1e-6)
    n_win, moving = 20_000, 0
    for _ in range(n_win):
        p = 40.0 + rng.normal(0.0, rng.uniform(0.1, 1.5), (20, 2))
        T, thr, _ = sl.test(p, 1e-6, np.arange(20))
        moving += T > thr
    assert moving / n_win <= 3e-3 + 4 * np.sqrt(1e-3 / n_win)


def test_slow_dot_is_moving_and_a_jittering_lamp_is_static():
    # a lamp jittering 1 px (1σ) per axis never reads as motion over 300 frames; a dot crawling
    # 0.3 px a frame (15 mm/s at 5 mm/px, 10 frames/s) with 0.3 px jitter does within 2 s, the
    # lamp's jitter being the scene's (measured: frame 17)
    rng = np.random.default_rng(2)
    sl = StaticLights()
    lamp, dot0 = np.array([50.0, 50.0]), np.array([150.0, 100.0])
    first_moving = None
    for k in range(300):
        lamp_k = lamp + rng.normal(0, 1.0, 2)
        dot_k = dot0 + [0.3 * k, 0.0] + rng.normal(0, 0.3, 2)
        s = sl.update(k, [lamp_k, dot_k], ["red", "red"])
        assert s[0] != MOVING
        if s[1] == MOVING and first_moving is None:
            first_moving = k
    assert s[0] == STATIC
    assert first_moving is not None and first_moving <= 2 * FPS


def test_detector_background_copes_with_the_real_scene():
    # the foreground model of running mean and variance: the dot is found on grass, brick, tape
    # and concrete in most visible frames, sub-pixel, with no rebuild of the background. Where
    # the dot was last seen is protected from the background update, as the tracking pipeline
    # does with its track (unprotected, a dot that stops for 1.5 s fades into the background:
    # 225 of 251 frames)
    scene = Overlay(**LAMPS)
    det = DotDetector(("red",))
    found, errs, n = 0, [], 0
    last = []
    for k, _, frame in scene.frames():
        dots = det.detect(frame, protect=last)
        last = [tuple(scene.uv[k])] if scene.drawn[k] else last
        if not scene.visible[k]:
            continue
        n += 1
        d = min(dots, key=lambda d: np.hypot(d.u - scene.uv[k, 0], d.v - scene.uv[k, 1]), default=None)
        if d is not None and np.hypot(d.u - scene.uv[k, 0], d.v - scene.uv[k, 1]) < 3.0:
            found += 1
            errs.append(np.hypot(d.u - scene.uv[k, 0], d.v - scene.uv[k, 1]))
    assert det.rebuilds == 0
    assert found / n >= 0.90                    # measured: 0.95
    assert np.median(errs) < 0.2                # px; measured: 0.08
