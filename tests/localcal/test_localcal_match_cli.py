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
    assert "matched 785 pose pairs (nearest stamps within 0.01 s) at a clock offset of +0.0 ms; 785 used, 0 dropped" \
        in text and f"wrote {out}" in text


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


# --------------------------------------------------------------------------- what match says and writes
def test_residuals_plot_and_the_new_json_keys(tmp_path, capsys):
    """fr2/desk ORB-SLAM2 (real): one residual row per pair, figures, and the counts in the JSON."""
    from matplotlib.image import imread

    out, res, plots = tmp_path / "r.json", tmp_path / "pairs.csv", tmp_path / "plots"
    cam, gt = DATA / "fr2_desk_ORB.txt", DATA / "fr2_desk_groundtruth.txt"
    rc = main(["localcal", "match", str(cam), str(gt), "--out", str(out), "--residuals", str(res), "--plot", str(plots)])
    assert rc == 0
    r = json.loads(out.read_text())
    for key in ("pairs_used", "pairs_dropped", "rmse_all_mm", "rmse_kept_mm", "duplicate_stamps", "notes",
                "time_offset_std_s", "time_offset_source", "pairing", "dropped"):
        assert key in r, key
    assert "std_scale" not in r and "scale_drift" not in r          # a rigid match
    assert r["pairs_used"] + r["pairs_dropped"] == r["n_pairs"] and r["rmse_kept_mm"] == r["rmse_mm"]
    assert r["time_offset_source"] == "zero" and r["time_offset_s"] == 0.0
    assert r["duplicate_stamps"] == 1                                # the ground truth repeats one stamp
    rows = np.genfromtxt(res, delimiter=",", names=True)
    assert len(rows) == r["n_pairs"] and int(rows["kept"].sum()) == r["pairs_used"]
    kept = rows["kept"] == 1
    assert np.sqrt(np.mean(rows["error_mm"][kept] ** 2)) == pytest.approx(r["rmse_kept_mm"], rel=1e-5)
    assert np.sqrt(np.mean(rows["error_mm"] ** 2)) == pytest.approx(r["rmse_all_mm"], rel=1e-5)
    np.testing.assert_allclose(np.sqrt(rows["ex_mm"] ** 2 + rows["ey_mm"] ** 2 + rows["ez_mm"] ** 2),
                               rows["error_mm"], atol=2e-4)
    src, dst = read_tum(cam), read_tum(gt)
    assert np.all(np.abs(src.t_s[rows["i_src"].astype(int)] - rows["t_src_s"]) < 1e-6)
    assert np.all(np.abs(dst.t_s[rows["i_dst"].astype(int)] - rows["t_dst_s"]) < 1e-6)
    for name in ("trajectories.png", "error.png"):
        img = imread(plots / name)
        assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 500
    text = capsys.readouterr().out
    assert f"wrote {res} ({r['n_pairs']} rows)" in text and f"wrote trajectories.png and error.png to {plots}" in text
    assert "note: fr2_desk_groundtruth.txt" in text or "note: " in text
    # the plot folder is not replaced without --overwrite, and the check comes before the work
    rc = main(["localcal", "match", str(cam), str(gt), "--out", str(out), "--plot", str(plots)])
    assert rc == 1 and "--plot" in capsys.readouterr().err
    assert main(["localcal", "match", str(cam), str(gt), "--out", str(out), "--plot", str(plots), "--overwrite"]) == 0


def test_streams_at_one_rate_with_an_offset_are_interpolated(tmp_path, capsys):
    """Camera and robot both at 10 Hz, the camera's frames halfway between the robot's (a 50 ms clock
    offset): no robot stamp lies within 20 ms of a camera stamp, so the robot poses are interpolated
    at the camera stamps, and a note says so."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(2)
    pose, dur = asymmetric_planar_path(rng)
    T = random_transform(rng, pose(np.zeros(1))[0][0])
    t_kin, t_cam = np.arange(0.0, dur, 0.1), np.arange(0.05, dur - 0.1, 0.1)

    def poses(t):
        p, R = pose(t)
        R = R @ Rotation.from_rotvec(0.2 * np.sin(t[:, None] * [0.3, 0.5, 0.7])).as_matrix()
        out = np.zeros((len(t), 4, 4))
        out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = R, p + rng.normal(0, 0.2, p.shape), 1.0
        return out

    write_tum(tmp_path / "cam.tum", Trajectory(t_cam, np.linalg.inv(T) @ poses(t_cam)))
    write_tum(tmp_path / "kin.tum", Trajectory(t_kin, poses(t_kin)))
    out = tmp_path / "r.json"
    rc = main(["localcal", "match", str(tmp_path / "cam.tum"), str(tmp_path / "kin.tum"), "--time-offset", "0",
               "--out", str(out)])
    r = json.loads(out.read_text())
    assert r["pairing"] == "interpolated" and r["n_pairs"] == len(t_cam)
    assert any(n.startswith(f"only 0 of the {len(t_cam)} ") and "interpolated at the" in n for n in r["notes"])
    # linear interpolation between 0.1 s samples of a curved path costs a few mm: within the reported std
    assert np.all(np.abs(np.array(r["t_mm"]) - T[:3, 3]) <= 3 * np.array(r["std_t_mm"]))
    assert rotation_error_deg(np.array(r["R"]), T[:3, :3]) < 0.5
    assert rc in (0, 1)
    capsys.readouterr()


def test_a_csv_of_tum_rows_is_read_as_tum_and_said(tmp_path, capsys):
    shutil_src = DATA / "freiburg1_xyz-rgbdslam.txt"
    cam = tmp_path / "cam.csv"
    cam.write_text(shutil_src.read_text())
    out = tmp_path / "r.json"
    rc = main(["localcal", "match", str(cam), str(DATA / "freiburg1_xyz-groundtruth.txt"), "--out", str(out)])
    assert rc == 0
    note = f"{cam}: TUM rows, though the suffix '.csv' suggests EuRoC: read as TUM (give --format to choose)"
    assert note in json.loads(out.read_text())["notes"]
    assert f"note: {note}" in capsys.readouterr().out
