"""Verdict of ``calibrate_handeye`` on good and bad eye-in-hand data: both error rates.

Run as a script for the full confusion table (``python -m tests.localcal.test_localcal_handeye_study
[SEEDS]``); the test runs one seed per case. A bad case counts as caught when the result is
``suspect`` or no estimate is made (a one-line error).
"""

import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.errors import PosekitError
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.handeye import calibrate_handeye
from tests.localcal.test_localcal_handeye import eye_in_hand


def _scaled(traj, k):
    T = traj.T.copy()
    T[:, :3, 3] *= k
    return Trajectory(traj.t_s, T)


def _slipped(seed):
    """The camera slips on its mount half-way: 20 mm and 2 deg."""
    cam, kin, X, Z = eye_in_hand(seed, duration_s=6.0)
    T = cam.T.copy()
    half = T.shape[0] // 2
    slip = np.eye(4)
    slip[:3, :3] = Rotation.from_rotvec(np.deg2rad([2.0, 0, 0])).as_matrix()
    slip[:3, 3] = [20.0, 0, 0]
    T[half:] = T[half:] @ slip
    return Trajectory(cam.t_s, T), kin, {}


def _mirrored(seed):
    cam, kin, _, _ = eye_in_hand(seed, duration_s=6.0)
    S = np.diag([1.0, 1.0, -1.0, 1.0])
    return Trajectory(cam.t_s, S @ cam.T @ S), kin, {}


def _random(seed):
    cam, kin, _, _ = eye_in_hand(seed, duration_s=6.0)
    rng = np.random.default_rng(seed)
    T = cam.T.copy()
    T[:, :3, :3] = Rotation.random(len(cam), random_state=rng).as_matrix()
    T[:, :3, 3] = rng.uniform(-1000, 1000, (len(cam), 3))
    return Trajectory(cam.t_s, T), kin, {}


def _case(**kw):
    def make(seed):
        cam, kin, _, _ = eye_in_hand(seed, **{"duration_s": 6.0, **kw})
        return cam, kin, {}
    return make


GOOD = {
    "240 mm lever": _case(),
    "80 mm lever": _case(lever_mm=80.0),
    "600 mm lever, 2 mm noise": _case(lever_mm=600.0, noise_mm=2.0),
    "10 % relocalisation jumps": _case(outliers=0.1),
    "rotation about 2 axes": _case(axes="xy"),
    "clock offset -0.4 s": _case(offset_s=-0.4),
    "15 Hz camera, 12 s": _case(cam_hz=15.0, duration_s=12.0),
    "isotropic 0.5 mm, 0.05 deg": _case(noise_mm=0.5, depth_factor=1.0, noise_deg=0.05),
}
BAD = {
    "rotation about 1 axis": _case(axes="z"),
    "camera in mm": lambda s: (lambda c, k: (_scaled(c, 1000.0), k, {}))(*eye_in_hand(s, duration_s=6.0)[:2]),
    "kinematic in mm": lambda s: (lambda c, k: (c, _scaled(k, 1000.0), {}))(*eye_in_hand(s, duration_s=6.0)[:2]),
    "camera of another motion": lambda s: (eye_in_hand(s + 1000, duration_s=6.0)[0], eye_in_hand(s, duration_s=6.0)[1],
                                           {}),
    "inverted camera poses": lambda s: (lambda c, k: (Trajectory(c.t_s, np.linalg.inv(c.T)), k, {}))(
        *eye_in_hand(s, duration_s=6.0)[:2]),
    "mirrored camera path": _mirrored,
    "camera slips 20 mm / 2 deg": _slipped,
    "random camera poses": _random,
    "clock offset beyond the search": lambda s: (*eye_in_hand(s, duration_s=8.0, offset_s=1.6)[:2], {}),
    "12 camera poses": lambda s: (lambda c, k: (Trajectory(c.t_s[::15], c.T[::15]), k, {}))(
        *eye_in_hand(s, duration_s=6.0)[:2]),
}


def verdict(make, seed) -> str:
    cam, kin, kw = make(seed)
    try:
        return calibrate_handeye(cam, kin, **kw).status
    except PosekitError:
        return "error"


def study(seeds, good=GOOD, bad=BAD) -> dict:
    """``{case: {"ok": n, "suspect": n, "error": n}}`` for every good and bad case."""
    table = {}
    for group in (good, bad):
        for name, make in group.items():
            counts = {"ok": 0, "suspect": 0, "error": 0}
            for seed in seeds:
                counts[verdict(make, seed)] += 1
            table[name] = counts
    return table


#: Good cases the test runs (the others are alike in test_localcal_handeye.py; all in the script).
_GOOD_IN_TEST = ("80 mm lever", "10 % relocalisation jumps", "15 Hz camera, 12 s")


@pytest.mark.parametrize("name", _GOOD_IN_TEST)
def test_no_good_case_is_refused(name):
    """One seed per case, each its own test (a few seconds; xdist spreads them)."""
    assert verdict(GOOD[name], 300) == "ok", name


@pytest.mark.parametrize("name", list(BAD))
def test_no_bad_case_is_ok(name):
    assert verdict(BAD[name], 300) != "ok", name


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    table = study(range(400, 400 + n))
    for group, label in ((GOOD, "good"), (BAD, "bad")):
        for name in group:
            c = table[name]
            print(f"{label:4s}  {name:32s} ok {c['ok']:3d}  suspect {c['suspect']:3d}  error {c['error']:3d}")
    g = sum(table[k]["suspect"] + table[k]["error"] for k in GOOD)
    b = sum(table[k]["ok"] for k in BAD)
    print(f"good refused: {g} of {n * len(GOOD)}; bad accepted (ok): {b} of {n * len(BAD)}")
