"""Tracker of the ceiling dots on synthetic world measurements (no video)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posekit.ceiling.track.cameras import Camera, MultiCameraTracker, border_distance, homography_jacobian
from posekit.ceiling.track.tracker import Tracker
from posekit.ceiling.track.types import CHI2_2DOF_999, TrackerConfig
from posekit.errors import ConfigError, GeometryError, TrajectoryError

FPS = 15.0          # the paper's camera
DT = 1.0 / FPS
SPEED = np.array([300.0, -150.0])     # mm/s, a ground robot


def straight_line(n, rng, noise_mm=3.0, start=(1000.0, 2000.0)):
    t = np.arange(n) * DT
    truth = np.asarray(start) + t[:, None] * SPEED
    return t, truth, truth + rng.normal(0.0, noise_mm, truth.shape)


def run(tracker, t, meas, present):
    return [tracker.step(ti, {"red": z} if p else {}) for ti, z, p in zip(t, meas, present)]


# --- status: ok / predicted / lost --------------------------------------------------------

def test_dropout_predicts_then_loses_and_never_ok_without_a_dot():
    rng = np.random.default_rng(0)
    t, truth, meas = straight_line(90, rng)
    present = np.ones(90, bool)
    present[30:36] = False            # 0.4 s in an air-conditioning hole: predicted
    present[50:75] = False            # 1.67 s: predicted for 1 s, then lost
    tr = Tracker(TrackerConfig(meas_std_mm=3.0, max_predict_s=1.0, min_move_mm=0.0))
    rows = run(tr, t, meas, present)
    status = np.array([r.status for r in rows])
    assert np.all(status[present] == "ok")
    assert np.all(status[30:36] == "predicted")
    # by default a dot that comes back after more than confirm_after_s must be seen moving
    # with the track once before it is ok again (a lamp where the dot was expected is not)
    rows2 = run(Tracker(TrackerConfig(meas_std_mm=3.0)), t, meas, present)
    status2 = np.array([r.status for r in rows2])
    assert status2[0] == "lost" and status2[36] == "predicted" and status2[76] == "ok"
    assert np.all((status2 == status) | (np.arange(90) == 0) | (np.arange(90) == 36) | (np.arange(90) == 75))
    gap = t[50:75] - t[49]
    assert np.all(status[50:75][gap <= 1.0 + 1e-9] == "predicted")
    assert np.all(status[50:75][gap > 1.0 + 1e-9] == "lost")
    lost = status == "lost"
    assert np.all(np.isnan([r.x for r in np.array(rows)[lost]]))
    assert all(r.csv_fields()[2:4] == ["", ""] for r in np.array(rows)[lost])
    # a constant-velocity prediction through the short dropout stays close to the truth
    err = np.hypot(*(np.array([[r.x, r.y] for r in rows[30:36]]) - truth[30:36]).T)
    assert err.max() < 15.0
    # after 'lost' the next detection re-initialises: ok again at once
    assert rows[75].status == "ok" and abs(rows[75].x - meas[75, 0]) < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=60), st.integers(0, 2 ** 16))
def test_ok_implies_a_dot_this_frame(present, seed):
    rng = np.random.default_rng(seed)
    n = len(present)
    t, _, meas = straight_line(n, rng)
    meas[rng.random(n) < 0.15] += rng.normal(0, 2000.0, 2)      # some wild outliers too
    rows = run(Tracker(), t, meas, present)
    for r, p in zip(rows, present):
        assert r.status in ("ok", "suspect", "predicted", "lost")
        if r.status in ("ok", "suspect"):               # suspect: accepted, but e.g. re-acquired far away
            assert p and "red" in r.measured
        if not p:
            assert r.status not in ("ok", "suspect") and r.measured == {}
        assert np.isfinite(r.x) == (r.status != "lost")
        assert bool(r.reasons) == (r.status != "ok")


def test_filter_reduces_noise_on_a_straight_line():
    rng = np.random.default_rng(1)
    t, truth, meas = straight_line(300, rng, noise_mm=5.0)
    tr = Tracker(TrackerConfig(meas_std_mm=5.0))
    rows = run(tr, t, meas, np.ones(300, bool))
    est = np.array([[r.x, r.y] for r in rows])[30:]
    raw = np.hypot(*(meas[30:] - truth[30:]).T).mean()
    filt = np.hypot(*(est - truth[30:]).T).mean()
    assert filt < 0.8 * raw


def test_follows_a_sharp_turn_without_gating_it_out():
    # 300 mm/s, 90° turns of 200 mm radius every 6 s (450 mm/s² centripetal), 3 mm noise
    rng = np.random.default_rng(4)
    t = np.arange(600) * DT
    w = np.where((t % 6.0) < np.pi / 2 * 200.0 / 300.0, 300.0 / 200.0, 0.0)
    th = np.cumsum(w) * DT
    truth = np.cumsum(np.column_stack([300 * np.cos(th), 300 * np.sin(th)]), axis=0) * DT
    meas = truth + rng.normal(0.0, 3.0, truth.shape)
    rows = run(Tracker(TrackerConfig(meas_std_mm=3.0, min_move_mm=0.0)), t, meas, np.ones(len(t), bool))
    assert all(r.status == "ok" for r in rows)
    err = np.hypot(*(np.array([[r.x, r.y] for r in rows]) - truth).T)[30:]
    raw = np.hypot(*(meas - truth).T)[30:]
    assert err.max() < 12.0 and err.mean() < 0.85 * raw.mean()


# --- gating --------------------------------------------------------------------------------

def test_outlier_rejected_then_tracking_goes_on():
    rng = np.random.default_rng(2)
    t, truth, meas = straight_line(40, rng)
    meas[20] += [400.0, -300.0]         # a reflection far from the dot
    tr = Tracker(TrackerConfig(meas_std_mm=3.0))
    rows = run(tr, t, meas, np.ones(40, bool))
    assert rows[20].status == "predicted" and rows[20].measured == {}
    assert np.hypot(rows[20].x - truth[20, 0], rows[20].y - truth[20, 1]) < 15.0
    assert tr.states["red"].n_rejected == 0          # reset by the next accepted frame
    assert all(r.status == "ok" for r in rows[21:])


def test_nearest_candidate_is_associated():
    tr = Tracker(TrackerConfig(meas_std_mm=2.0))
    for k in range(10):
        tr.step(k * DT, {"red": [100.0 + 30 * k * DT, 0.0]})
    t = 10 * DT
    row = tr.step(t, {"red": [[900.0, 900.0], [100.0 + 30 * t, 0.5], [-500.0, 0.0]]})
    assert row.status == "ok"
    assert row.measured["red"] == pytest.approx((100.0 + 30 * t, 0.5))


def test_consistent_jump_reinitialises_after_reinit_after_frames():
    tr = Tracker(TrackerConfig(meas_std_mm=2.0, reinit_after=4, min_move_mm=0.0))
    for k in range(10):
        tr.step(k * DT, {"red": [0.0, 0.0]})
    rows = [tr.step((10 + k) * DT, {"red": [2000.0, 0.0]}) for k in range(4 + 16)]   # robot carried away
    # re-initialised on the 4th frame, but a jump away from a live prediction is suspect for
    # max_predict_s (the old dot may only be hidden), then ok
    assert [r.status for r in rows[:4]] == ["predicted"] * 3 + ["suspect"]
    assert rows[3].x == pytest.approx(2000.0) and "re-acquired 2000 mm from where" in rows[3].reason
    assert all(r.status == "suspect" for r in rows[3:18]) and rows[19].status == "ok"


def test_abrupt_stop_is_a_manoeuvre_not_an_outlier():
    # 300 mm/s, then standing still from one frame to the next (the renderer's robot stops
    # at each corner to turn on the spot): 20 mm off the prediction, far outside the χ²
    # gate with 0.3 mm noise, but inside gate_floor_mm: followed at once
    rng = np.random.default_rng(5)
    t = np.arange(60) * DT
    truth = np.column_stack([np.minimum(t, 2.0) * 300.0, np.zeros_like(t)])
    meas = truth + rng.normal(0.0, 0.3, truth.shape)
    tr = Tracker(TrackerConfig(meas_std_mm=0.3, min_move_mm=0.0))
    rows = run(tr, t, meas, np.ones(len(t), bool))
    assert all(r.status == "ok" for r in rows)
    err = np.hypot(*(np.array([[r.x, r.y] for r in rows]) - truth).T)
    assert err[31:].max() < 3.0 and err[40:].max() < 1.0


def test_gate_is_chi2_999():
    assert CHI2_2DOF_999 == pytest.approx(13.8155, abs=1e-3)     # scipy.stats.chi2.ppf(0.999, 2)


# --- heading (case B) -------------------------------------------------------------------------

def rotating_robot(n, rng, noise_mm=2.0, d_mm=400.0, rate=0.8):
    """Red dot on the robot centre, green 400 mm ahead; the robot turns on the spot and
    drives a circle, passing the ±180° wrap several times."""
    t = np.arange(n) * DT
    theta = rate * t - 3.0
    centre = np.column_stack([1500 + 800 * np.cos(0.2 * t), 1500 + 800 * np.sin(0.2 * t)])
    green = centre + d_mm * np.column_stack([np.cos(theta), np.sin(theta)])
    return (t, theta, centre, green, centre + rng.normal(0, noise_mm, centre.shape),
            green + rng.normal(0, noise_mm, green.shape))


def test_heading_from_two_dots_through_the_wrap():
    rng = np.random.default_rng(3)
    t, theta, _, _, red, green = rotating_robot(300, rng)
    tr = Tracker(TrackerConfig(dots=("red", "green"), meas_std_mm=2.0, min_move_mm=0.0))
    rows = [tr.step(ti, {"red": r, "green": g}) for ti, r, g in zip(t, red, green)]
    h = np.radians([r.heading_deg for r in rows])
    assert np.all((h > -np.pi) & (h <= np.pi))
    err = np.degrees(np.angle(np.exp(1j * (h - theta))))[10:]
    # raw heading std is sqrt(2)·2/400 rad = 0.41°; the filter must not do worse, wrap included
    assert np.abs(err).max() < 2.0
    assert np.std(err) < 0.45


def test_heading_empty_with_one_dot_and_when_green_lost():
    tr = Tracker()
    assert np.isnan(tr.step(0.0, {"red": [0.0, 0.0]}).heading_deg)
    tr2 = Tracker(TrackerConfig(dots=("red", "green"), max_predict_s=0.5, min_move_mm=0.0))
    row = tr2.step(0.0, {"red": [0.0, 0.0], "green": [0.0, 400.0]})
    assert row.heading_deg == pytest.approx(90.0)
    assert row.csv_fields()[4] == "90.000"
    row = tr2.step(0.3, {"red": [0.0, 0.0]})                 # green in a hole: predicted heading
    assert row.heading_deg == pytest.approx(90.0, abs=1e-6)
    row = tr2.step(0.8, {"red": [0.0, 0.0]})                 # green gone longer than 0.5 s
    assert np.isnan(row.heading_deg) and row.dots["green"][2] == "lost"
    assert row.status == "ok" and row.csv_fields()[4] == ""


# --- bad input ----------------------------------------------------------------------------------

def test_bad_input():
    tr = Tracker()
    tr.step(1.0, None)
    with pytest.raises(TrajectoryError, match="went back from 1.000000 s to 0.500000 s"):
        tr.step(0.5, None)
    with pytest.raises(TrajectoryError, match="finite"):
        tr.step(float("nan"), None)
    with pytest.raises(GeometryError, match=r"shape \(2,\) or \(K, 2\).*got shape \(3,\)"):
        tr.step(2.0, {"red": [1.0, 2.0, 3.0]})
    with pytest.raises(GeometryError, match=r"\['blue'\] are not tracked"):
        tr.step(2.0, {"blue": [1.0, 2.0]})
    with pytest.raises(ConfigError, match="TrackerConfig.dots"):
        TrackerConfig(dots=("red", "red"))
    with pytest.raises(ConfigError, match="TrackerConfig.max_predict_s"):
        TrackerConfig(max_predict_s=-1)
    with pytest.raises(ConfigError, match="at least one camera"):
        MultiCameraTracker([])


# --- several cameras (case D) --------------------------------------------------------------------

class AffineCal:
    """A calibration stub: world = A·uv + b (a homography with last row [0, 0, 1])."""

    def __init__(self, scale, offset, rms_px=0.3):
        self.H_world_image = np.array([[scale, 0, offset[0]], [0, scale, offset[1]], [0, 0, 1.0]])
        self.H_image_world = np.linalg.inv(self.H_world_image)
        self.rms_px = rms_px

    @staticmethod
    def _apply(H, p):
        p = np.asarray(p, float).reshape(-1, 2)
        q = np.c_[p, np.ones(len(p))] @ H.T
        return q[:, :2] / q[:, 2:]

    def image_to_world(self, uv):
        return self._apply(self.H_world_image, uv)

    def world_to_image(self, xy):
        return self._apply(self.H_image_world, xy)


def test_homography_jacobian_and_border_distance():
    H = np.array([[5.0, 0.3, 10.0], [0.2, 6.0, -4.0], [1e-4, 2e-4, 1.0]])
    uv = np.array([[100.0, 200.0], [800.0, 50.0]])
    J = homography_jacobian(lambda p: AffineCal._apply(H, p), uv)
    for k, (u, v) in enumerate(uv):
        w = H @ [u, v, 1.0]
        x = w[:2] / w[2]
        Ja = (H[:2, :2] - np.outer(x, H[2, :2])) / w[2]
        np.testing.assert_allclose(J[k], Ja, rtol=1e-6)
    np.testing.assert_allclose(border_distance([[0, 0], [431.5, 239.5], [900, 10]], (864, 480)),
                               [0.5, 240.0, -36.5])


def test_multicamera_switches_to_the_camera_that_sees_the_dot():
    # two 400x300 cameras at 5 mm/px: A covers x in [0, 2000], B x in [1500, 3500] (overlap 500 mm)
    cams = [Camera(AffineCal(5.0, (0.0, 0.0)), (400, 300), "A"),
            Camera(AffineCal(5.0, (1500.0, 0.0)), (400, 300), "B")]
    mct = MultiCameraTracker(cams, TrackerConfig(meas_std_mm=2.0, min_move_mm=0.0), border_margin_px=20.0)
    n = 150
    t = np.arange(n) * DT
    truth = np.column_stack([200 + 300 * t, 700 + 0 * t])   # 200 → 3170 mm along x
    rows, used = [], []
    for ti, p in zip(t, truth):
        det = []
        for cam in cams:
            uv = cam.calibration.world_to_image(p)[0]
            inside = border_distance(uv[None], cam.image_size)[0] > 0
            det.append({"red": uv} if inside else None)
        row = mct.step(ti, det)
        rows.append(row)
        used.append(row.camera)
    used = np.array(used)
    assert all(r.status == "ok" for r in rows)
    assert used[0] == 0 and used[-1] == 1
    switch = np.flatnonzero(np.diff(used))
    assert len(switch) == 1                                   # hysteresis: switch once, no flapping
    # switched in the overlap, once A's dot came within 20 px (100 mm) of A's border
    x_switch = truth[switch[0] + 1, 0]
    assert 1500 < x_switch and 2000 - x_switch <= 100 + 300 * DT
    err = np.hypot(*(np.array([[r.x, r.y] for r in rows]) - truth).T)
    assert err.max() < 3.0
    # predicted image positions feed the ROI of the camera(s) whose image contains the dot
    pred = mct.predicted_uv(t[-1] + DT)
    assert "red" in pred[1] and "red" not in pred[0]


def test_multicamera_prefers_dot_far_from_border_when_starting():
    cams = [Camera(AffineCal(5.0, (0.0, 0.0)), (400, 300), "A"),
            Camera(AffineCal(5.0, (1500.0, 0.0)), (400, 300), "B")]
    mct = MultiCameraTracker(cams, TrackerConfig(min_move_mm=0.0))
    p = np.array([1900.0, 700.0])             # 20 px from A's right border, 80 px inside B
    row = mct.step(0.0, [{"red": c.calibration.world_to_image(p)[0]} for c in cams])
    assert row.camera == 1 and row.status == "ok"
