"""Two robots with one red dot each (paper §III-B): two tracks with ids, no identity swap
when they cross or pass within a few dot diameters (independent generator of
``test_track_scene.py``), and the CLI's ``robot`` column."""

import json

import cv2
import numpy as np
import pytest

from posekit.ceiling.track.multitrack import MultiRobotTracker, track_robots_frames
from posekit.ceiling.track.pipeline import read_track_csv
from posekit.errors import ConfigError
from tests.ceiling.test_track_scene import FPS, H_IMAGE_WORLD, H, Scene, W
from tests.cli_helpers import assert_one_line_error, run_cli

N = 90
T = np.arange(N) / FPS


def paths(kind):
    if kind == "cross":              # an X: the dots overlap for a frame or two
        a = np.c_[800 + 300 * T, 700 + 200 * T]
        b = np.c_[800 + 300 * T, 700 + 200 * T[-1] - 200 * T]
    else:                            # head-on, side by side `kind` mm apart (the dot is ~70 mm wide)
        a = np.c_[800 + 300 * T, 1000 + 0 * T]
        b = np.c_[800 + 300 * T[-1] - 300 * T, 1000 + kind + 0 * T]
    return a, b


def identities(res, a, b):
    """Per robot: which path each ok row is on (0 = a, 1 = b, -1 = near both or neither)."""
    out = []
    for i in range(2):
        xy, ok = res.xy(i), res.status(i) == "ok"
        da, db = np.hypot(*(xy - a).T), np.hypot(*(xy - b).T)
        on = np.where((da < 10) & (db >= 10), 0, np.where((db < 10) & (da >= 10), 1, -1))
        out.append(on[ok])
    return out


@pytest.mark.parametrize("kind", ["cross", 60.0, 150.0])
def test_two_robots_keep_their_identity(kind):
    a, b = paths(kind)
    sc = Scene(n=N, seed=3, path=a, extra_paths=[b])
    res = track_robots_frames(sc.frames(), sc.camera(), 2)
    assert len(res) == 2 * N and [r.robot for r in res.rows[:4]] == [0, 1, 0, 1]
    ids = identities(res, a, b)
    first = [int(i[i >= 0][0]) for i in ids]
    assert sorted(first) == [0, 1]                                   # one robot per dot
    for i in range(2):
        assert np.all(ids[i][ids[i] >= 0] == first[i])               # no swap, ever
        assert np.count_nonzero(ids[i] == -1) <= 4                   # only where the dots touch
        assert np.count_nonzero(res.status(i) == "ok") >= 0.8 * N


def test_multi_robot_tracker_on_world_points():
    mrt = MultiRobotTracker(2)
    rows = []
    for k in range(30):
        t = k / FPS
        rows.append(mrt.step(t, np.array([[300 * t, 0.0], [1000 - 300 * t, 40.0]])))
    last = rows[-1]
    assert [r.status for r in last] == ["ok", "ok"]
    got = sorted((r.x, r.y) for r in last)
    np.testing.assert_allclose(got, sorted([(300 * 29 / FPS, 0.0), (1000 - 300 * 29 / FPS, 40.0)]), atol=1e-6)
    with pytest.raises(ConfigError, match="n_robots: expected an integer >= 1, got 0"):
        MultiRobotTracker(0)


def test_cli_two_robots_robot_column(capsys, tmp_path):
    a, b = paths(150.0)
    sc = Scene(n=N, seed=4, path=a, extra_paths=[b])
    w = cv2.VideoWriter(str(tmp_path / "v.avi"), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (W, H))
    for _, _, img in sc.frames():
        w.write(img)
    w.release()
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"H_image_world": H_IMAGE_WORLD.tolist(),
                               "H_world_image": np.linalg.inv(H_IMAGE_WORLD).tolist(), "rms_px": 0.05,
                               "rms_world": 0.5}))
    for flags in (["--dots", "red,red"], ["--robots", "2"]):
        rc, out, err = run_cli(capsys, "ceiling", "track", tmp_path / "v.avi", "--calibration", cal, *flags,
                               "--out", tmp_path / "t.csv")
        assert rc == 0, err
        assert f"{N} frames x 2 robots: " in out
        lines = (tmp_path / "t.csv").read_text().splitlines()
        assert lines[0] == "frame,time_s,x,y,heading_deg,status,std_mm,std_heading_deg,reason,robot"
        t = read_track_csv(tmp_path / "t.csv")
        assert list(t["robot"][:4]) == [0, 1, 0, 1] and list(t["frame"][:4]) == [0, 0, 1, 1]
        for i in range(2):
            sel = (t["robot"] == i) & (t["status"] == "ok")
            xy = np.c_[t["x"], t["y"]][sel]
            d = np.minimum(np.hypot(*(xy - a[t["frame"][sel]]).T), np.hypot(*(xy - b[t["frame"][sel]]).T))
            assert np.count_nonzero(sel) >= 0.8 * N and d.max() < 5.0
    assert_one_line_error(*run_cli(capsys, "ceiling", "track", tmp_path / "v.avi", "--calibration", cal, "--dots",
                                   "red,red", "--robots", "3", "--out", tmp_path / "t.csv"),
                          "--dots red,red means two robots; got --robots 3")
    assert_one_line_error(*run_cli(capsys, "ceiling", "track", tmp_path / "v.avi", "--calibration", cal, "--dots",
                                   "red,green", "--robots", "2", "--out", tmp_path / "t.csv"),
                          "--robots: several robots are tracked with one red dot each")


def test_multi_robot_no_confident_jump_to_a_decoy_and_rivals_are_suspect():
    # two robots at 300 mm/s, 1 m apart (world points, each verified and found moving). Robot 0's
    # dot is hidden for 1 s while a third laser-like spot moves 1.2 m away, then it reappears.
    # The jump to that spot is suspect (probation, then the previous dot seen again: which is the
    # laser cannot be told), never ok off robot 0's path; robot 1 is suspect while the spot, that
    # no robot claims, is in view outside its gate. (Before this change robot 1 stayed ok with
    # the spot in view; hidden 1.6 s, longer than max_predict_s, the lost robot 0 started on
    # the spot as ok, 1.2 m off, now it is suspect for max_predict_s first.)
    n = 90
    t = np.arange(n) / FPS
    a = np.c_[300 * t, np.zeros(n)]
    b = np.c_[300 * t, np.full(n, 1000.0)]
    decoy = np.c_[300 * t, np.full(n, -1200.0)]
    hidden = (t >= 2.0) & (t < 3.0)
    mrt = MultiRobotTracker(2)
    rows = []
    for k in range(n):
        pts = ([] if hidden[k] else [a[k]]) + [b[k]] + ([decoy[k]] if t[k] >= 2.0 else [])
        rows.append(mrt.step(t[k], np.array(pts), moving=np.ones(len(pts), bool)))
    r0 = [r[0] for r in rows]
    r1 = [r[1] for r in rows]
    off0 = [np.hypot(r.x - a[k, 0], r.y - a[k, 1]) > 50 for k, r in enumerate(r0)]
    assert not any(r.status == "ok" and off for r, off in zip(r0, off0))
    assert any(r.status == "suspect" for r in r0)
    assert all(r.status == "ok" for r in r1[5:30])                    # before the spot appears
    assert any(r.status == "suspect" and "another moving" in r.reason for r in r1[30:])
    assert all(np.hypot(r.x - b[k, 0], r.y - b[k, 1]) < 50 for k, r in enumerate(r1) if r.status == "ok")
