"""``posekit localcal match`` end to end: real TUM pairs, synthetic pairs in both modes, bad input."""

import json

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.localcal.registration.alignment import umeyama
from posekit.localcal.registration.association import associate
from posekit.localcal.registration.tum import Trajectory, read_tum, write_tum
from tests.localcal.synth_trajectories import (
    TUM_DATA as DATA,
)
from tests.localcal.synth_trajectories import (
    asymmetric_planar_path,
    make_pair,
    random_transform,
    rotation_error_deg,
)

KEYS = ["R", "t_mm", "rmse_mm", "mean_abs_err_mm", "max_abs_err_mm"]


def test_match_real_tum_pair_writes_the_contract(tmp_path, capsys):
    out = tmp_path / "r.json"
    cam, gt = DATA / "freiburg1_xyz-rgbdslam.txt", DATA / "freiburg1_xyz-groundtruth.txt"
    rc = main(["localcal", "match", str(cam), str(gt), "--max-dt", "0.01", "--time-offset", "0", "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert list(res)[:5] == KEYS
    assert np.shape(res["R"]) == (3, 3) and len(res["t_mm"]) == 3
    assert len(res["mean_abs_err_mm"]) == 3 and len(res["max_abs_err_mm"]) == 3
    src, dst = read_tum(cam), read_tum(gt)
    i, j = associate(src.t_s, dst.t_s, max_dt_s=0.01)
    R0, t0, _ = umeyama(src.positions[i], dst.positions[j])
    np.testing.assert_allclose(res["R"], R0, atol=1e-9)
    np.testing.assert_allclose(res["t_mm"], t0, atol=1e-6)
    assert res["rmse_mm"] == pytest.approx(13.47, abs=0.01)
    assert res["n_pairs"] == 785
    text = capsys.readouterr().out
    assert "matched 785 pose pairs within 0.01 s" in text and f"wrote {out}" in text


@pytest.mark.parametrize("flags", [[], ["--no-timestamps"]])
def test_match_recovers_synthetic_camera_to_base(tmp_path, flags):
    rng = np.random.default_rng(21)
    pose, dur = asymmetric_planar_path(rng)
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    src, dst = make_pair(rng, pose, dur, T_B_W=T, offset_s=0.25)
    write_tum(tmp_path / "cam.tum", src)
    write_tum(tmp_path / "kin.tum", dst)
    out = tmp_path / "r.json"
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), *flags, "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    R = np.array(res["R"])
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-9)
    assert rotation_error_deg(R, T[:3, :3]) < 0.5
    assert np.linalg.norm(np.array(res["t_mm"]) - T[:3, 3]) < 5.0
    if not flags:
        assert res["time_offset_s"] == pytest.approx(0.25, abs=3e-3)


def _write(path, rows):
    path.write_text("".join(" ".join(str(v) for v in r) + "\n" for r in rows))
    return str(path)


def _square(n=20, t0=0.0):
    """n poses on a 3D helix, TUM rows (s, m, qx qy qz qw)."""
    a = np.linspace(0, 3 * np.pi, n)
    return [(t0 + 0.1 * k, 0.3 * np.cos(a[k]), 0.3 * np.sin(a[k]), 0.05 * a[k], 0, 0, 0, 1) for k in range(n)]


@pytest.mark.parametrize(("case", "message"), [
    ("nan", "cam.tum:2: expected finite numbers, found NaN or infinity"),
    ("short_row", "cam.tum:2: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found 4 fields"),
    ("empty", "cam.tum: no poses found (expected lines 'timestamp tx ty tz qx qy qz qw')"),
    ("few", "cam.tum: 3 poses, at least 6 are needed for trajectory matching"),
    ("line", ("cam.tum: the path is a straight line (spread 0.0 mm across vs 99.9 mm along it), so the "
             "rotation about it is undetermined; trajectory matching needs a planar or 3D path")),
    ("no_overlap", ("no overlapping timestamps: cam.tum spans 100.000-101.900 s and kin.tum spans 0.000-1.900 s, "
                   "which overlap by fewer than 6 poses for any clock offset within ±1 s")),
    ("missing", "cam.tum: no such file; expected a TUM trajectory file ('timestamp tx ty tz qx qy qz qw' per line)"),
])
def test_bad_input_gives_one_line_errors(tmp_path, capsys, monkeypatch, case, message):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path / "kin.tum", _square())
    rows = _square()
    if case == "nan":
        rows[1] = (rows[1][0], "nan", *rows[1][2:])
    elif case == "short_row":
        rows[1] = rows[1][:4]
    elif case == "empty":
        rows = []
    elif case == "few":
        rows = rows[:3]
    elif case == "line":
        rows = [(0.1 * k, 0.01 * k, 0.01 * k, 0.01 * k, 0, 0, 0, 1) for k in range(20)]
    elif case == "no_overlap":
        rows = _square(t0=100.0)
    if case != "missing":
        _write(tmp_path / "cam.tum", rows)
    rc = main(["localcal", "match", "cam.tum", "kin.tum", "--out", "r.json"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err == f"posekit: error: {message}\n"
    assert not (tmp_path / "r.json").exists()


def test_bad_options_are_one_line_errors(tmp_path, capsys):
    traj = Trajectory(np.arange(20) * 0.1, np.broadcast_to(np.eye(4), (20, 4, 4)).copy())
    traj.T[:, :3, 3] = np.random.default_rng(0).normal(0, 100, (20, 3))
    write_tum(tmp_path / "a.tum", traj)
    a = str(tmp_path / "a.tum")
    rc = main(["localcal", "match", a, a, "--max-dt", "0", "--out", str(tmp_path / "r.json")])
    assert rc == 1
    assert capsys.readouterr().err == "posekit: error: max_dt_s must be a number > 0, got 0\n"
    (tmp_path / "no").write_text("a file, not a folder")
    rc = main(["localcal", "match", a, a, "--out", str(tmp_path / "no" / "r.json")])
    err = capsys.readouterr().err
    assert rc == 1 and err.startswith(f"posekit: error: --out {tmp_path / 'no' / 'r.json'}: cannot write in")
    assert err.count("\n") == 1


# ------------------------------------------------------------------ verdict, uncertainty, matcher (issue 14)
def test_match_json_carries_verdict_and_uncertainty(tmp_path):
    out = tmp_path / "r.json"
    cam, gt = DATA / "fr2_desk_ORB.txt", DATA / "fr2_desk_groundtruth.txt"
    rc = main(["localcal", "match", str(cam), str(gt), "--max-dt", "0.01", "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert list(res)[:9] == [*KEYS, "status", "reasons", "std_rot_deg", "std_t_mm"]
    assert res["status"] == "ok" and res["reasons"] == []
    assert len(res["std_rot_deg"]) == 3 and len(res["std_t_mm"]) == 3
    assert all(0 < v < 1.0 for v in res["std_rot_deg"]) and all(0 < v < 30.0 for v in res["std_t_mm"])


def test_suspect_match_writes_the_json_then_exits_1(tmp_path, capsys):
    """A camera 240 mm from the tool on a turning path: the hand-eye case, flagged."""
    from tests.localcal.test_localcal_verdict import lever
    src, dst, T = lever(3)
    write_tum(tmp_path / "cam.tum", src)
    write_tum(tmp_path / "kin.tum", dst)
    out = tmp_path / "r.json"
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 1
    res = json.loads(out.read_text())
    assert res["status"] == "suspect"
    assert any("use `posekit localcal handeye`" in r for r in res["reasons"])
    assert captured.err.startswith("posekit: suspect match: ") and captured.err.count("\n") == 1
    assert f"wrote {out}" in captured.out


def test_camera_file_in_millimetres_is_a_one_line_error(tmp_path, capsys):
    rng = np.random.default_rng(21)
    pose, dur = asymmetric_planar_path(rng)
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    src, dst = make_pair(rng, pose, dur, T_B_W=T, offset_s=0.0)
    W = src.T.copy()
    W[:, :3, 3] *= 1000.0
    write_tum(tmp_path / "cam.tum", Trajectory(src.t_s, W))
    write_tum(tmp_path / "kin.tum", dst)
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--out",
               str(tmp_path / "r.json")])
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1
    assert err.startswith("posekit: error: /") and "cam.tum moves 993x as far as" in err
    assert len(err) <= 301                                            # one line of at most 300 characters
    assert ("along the main axis), not the same motion in one unit; is it in millimetres? trajectory files are in "
            "metres; unknown scale: --with-scale\n") in err
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("matcher", ["cpd", "hybrid"])
def test_matcher_option_without_timestamps(tmp_path, matcher):
    from tests.localcal.test_localcal_verdict import base
    src, dst, T, _ = base(31, "smooth")
    write_tum(tmp_path / "cam.tum", src)
    write_tum(tmp_path / "kin.tum", dst)
    out = tmp_path / "r.json"
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--no-timestamps",
               "--matcher", matcher, "--format", "tum", "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())
    assert res["matcher"] == matcher and res["mode"] == "no-timestamps"
    assert rotation_error_deg(np.array(res["R"]), T[:3, :3]) < 0.3
    assert np.linalg.norm(np.array(res["t_mm"]) - T[:3, 3]) < 3.0
