"""Recorded episodes (DESIGN.md, seam): the folder format, its reader's one-line errors, and a
recorded simulated run that reproduces the run."""

import math
import shutil

import numpy as np
import pytest

from posekit.errors import ConfigError, InputFileError
from posekit.geometry import matrix_from_rotation_vector
from posekit.seam.frontend.config import apply_overrides, config_from_dict
from posekit.seam.frontend.episode import run_episode
from posekit.seam.frontend.logs import log_columns, read_episode_log, write_episode_log
from posekit.seam.frontend.profile import DEFAULT_PROFILE, load_profile, merge_profile, write_profile
from posekit.seam.frontend.simulate import simulate_data
from posekit.seam.frontend.tracker import track_log, track_metrics


def _small(sensors=None, **over):
    data = {"trajectory": {"steps": 60}, "filter": {"particles": 150}}
    for k, v in over.items():
        data.setdefault(k, {}).update(v)
    if sensors is not None:
        data["cell"] = {"sensors": sensors}
    return config_from_dict(data)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    cfg = _small()
    seed = 12
    data = simulate_data(cfg, seed)
    folder = tmp_path_factory.mktemp("log")
    write_episode_log(folder, cfg, data, seed)
    return cfg, seed, data, folder


def test_recorded_simulated_run_reproduces_the_run(recorded):
    cfg, seed, data, folder = recorded
    res = run_episode(cfg, seed, data=data)
    log = read_episode_log(folder)
    assert log.qref.shape == (60, 6) and log.laser_mm.shape == (60, 2, 2)
    tr = track_log(log)
    # the same filter on the same numbers: equal up to the CSV's round trip (exact repr) and
    # the force's turn into the tool frame and back
    assert np.abs(tr.estimate - res.estimate).max() < 1e-6
    assert np.abs(tr.truth - res.truth).max() < 1e-9
    m = track_metrics(tr)
    assert sum(m["status_counts"].values()) == 60
    rm = np.sqrt(np.mean(res.error ** 2, axis=0))  # mm, rad
    assert m["rmse_mm"]["x"] == pytest.approx(rm[0], abs=1e-5)
    assert m["rmse_deg"]["rz"] == pytest.approx(np.degrees(rm[5]), abs=1e-5)


def test_log_force_is_in_the_tool_frame_of_the_measured_pose(recorded):
    cfg, _, data, folder = recorded
    log = read_episode_log(folder)
    R = data.nominal.chain.forward_kinematics(data.q_meas)[:, :3, :3]
    f_base = np.einsum("tij,tj->ti", R, log.force_tool_n)
    assert np.abs(f_base - data.force_meas_n).max() < 1e-9
    # the process force (tool frame) is mostly along -z of the tool (pressing down): the mean
    # reading lies near the configured (100, -1000, -5000) N
    assert np.allclose(log.force_tool_n.mean(axis=0), cfg.simulation.force_n, atol=400.0)


def test_rotated_sensor_mount_reading_matches_a_hand_computed_plane_cut():
    """A sensor 30 mm ahead and 5 mm to the side, turned 25° about its z axis: its reading on a
    straight seam is the plane-line intersection computed here by hand (noise 0)."""
    M = np.eye(4)
    M[:3, :3] = matrix_from_rotation_vector(np.array([0.0, 0.0, math.radians(25.0)]))
    M[:3, 3] = [5.0, 30.0, 0.0]
    cfg = _small(trajectory={"kind": "line"}, sensors={"count": 1, "mounts": [M.tolist()]},
                 simulation={"laser_noise_mm": 0.0})
    data = simulate_data(cfg, 3)
    p0 = np.array(cfg.trajectory.start_mm)
    d = np.array([0.0, 1.0, 0.0])       # the line seam runs along base +y from the start
    for k in (0, 30, 59):
        S = data.truth[k] @ M
        o, x_s, n, z_s = S[:3, 3], S[:3, 0], S[:3, 1], S[:3, 2]
        s = n @ (o - p0) / (n @ d)
        e = p0 + s * d - o
        assert data.laser_mm[k, 0] == pytest.approx([x_s @ e, z_s @ e], abs=1e-9)


def _mount(rz_deg, t_mm):
    M = np.eye(4)
    M[:3, :3] = matrix_from_rotation_vector(np.array([0.0, 0.0, math.radians(rz_deg)]))
    M[:3, 3] = t_mm
    return M.tolist()


def test_filter_uses_the_mount_a_wrong_mount_in_setup_is_caught(tmp_path):
    """Two sensors turned 25° and -15° about their z axes: tracked with the right mounts the
    filter beats kinematics; the same log with setup.yaml claiming straight sensors gives errors
    several times larger, and the integrity verdict does not call those steps tracking. (The
    default profile's values with no cell named: what is tested is the innovations' verdict, not
    the profile's cell check, which alone makes both degraded: the default was fitted on sensors
    20 / 40 mm ahead.)"""
    mounts = [_mount(25.0, [5.0, 30.0, 0.0]), _mount(-15.0, [-5.0, 50.0, 2.0])]
    cfg = _small(sensors={"count": 2, "mounts": mounts})
    data = simulate_data(cfg, 6)
    (tmp_path / "ok").mkdir()
    write_episode_log(tmp_path / "ok", cfg, data, 6)
    anywhere = write_profile(tmp_path / "anywhere.yaml",
                             merge_profile(load_profile(DEFAULT_PROFILE), {}))   # (no `fitted`)
    good = track_metrics(track_log(read_episode_log(tmp_path / "ok", profile=anywhere)))
    (tmp_path / "bad").mkdir()
    wrong = _small(sensors={"count": 2, "distances_mm": [30.0, 50.0]})
    write_episode_log(tmp_path / "bad", wrong, data, 6)   # the same rows, the mounts of the wrong setup
    bad = track_metrics(track_log(read_episode_log(tmp_path / "bad", profile=anywhere)))
    default = track_log(read_episode_log(tmp_path / "ok"))
    assert set(default.status) == {"degraded"}, default.status
    assert all(r.startswith("the profile was fitted on another cell (sensor 1's mount ") for r in default.reason)
    # measured: x 0.152 vs 0.223 mm, z 0.197 vs 0.305 mm (kinematics with the compliance model: the
    # deflection); the wrong mounts 0.532 mm in x, every step lost
    assert good["rmse_mm"]["x"] < 0.8 * good["kinematic_rmse_mm"]["x"]
    assert good["rmse_mm"]["z"] < 0.75 * good["kinematic_rmse_mm"]["z"]
    assert bad["rmse_mm"]["x"] > 3.0 * good["rmse_mm"]["x"]
    assert good["status_counts"].get("tracking", 0) >= 55
    assert bad["status_counts"].get("tracking", 0) <= 6


def test_laser_samples_at_their_own_times_get_interpolated_joints(tmp_path):
    """Every other row a laser-only sample (joints and force empty, as a sensor sampling between
    the robot's joint messages): the joints are interpolated linearly in time and the track
    stays about as good (fine sampling: 0.6 mm of travel per row)."""
    cfg = _small(trajectory={"steps": 80, "length_mm": 50.0})
    data = simulate_data(cfg, 12)
    folder = tmp_path / "full"
    folder.mkdir()
    write_episode_log(folder, cfg, data, 12)
    shutil.copytree(folder, tmp_path / "sparse")
    lines = (folder / "log.csv").read_text().splitlines()
    assert lines[0].split(",") == log_columns(6, 2)
    out = [lines[0]]
    for i, line in enumerate(lines[1:]):
        f = line.split(",")
        if i % 2 == 1 and i < len(lines) - 2:
            f[1:16] = [""] * 15          # qref_1..6, q_1..6, fx_n..fz_n
        out.append(",".join(f))
    (tmp_path / "sparse" / "log.csv").write_text("\n".join(out) + "\n")
    log = read_episode_log(tmp_path / "sparse")
    assert log.interpolated.sum() == 39
    k = 3
    assert log.qref[k] == pytest.approx(0.5 * (data.nominal.q[k - 1] + data.nominal.q[k + 1]), abs=1e-12)
    assert np.abs(log.qref - data.nominal.q).max() < 2e-4
    m = track_metrics(track_log(log))
    full = track_metrics(track_log(read_episode_log(folder)))
    for a in ("x", "z"):
        assert m["rmse_mm"][a] < 2.0 * full["rmse_mm"][a] + 0.05, a
        assert m["rmse_mm"][a] < 0.5 * m["kinematic_rmse_mm"][a], a


# ------------------------------------------------------------------------- bad logs

def _edit(folder, tmp_path, name, fn):
    dst = tmp_path / "edited"
    shutil.copytree(folder, dst)
    p = dst / name
    p.write_text(fn(p.read_text()))
    return dst


def _line(text, i, fn):
    lines = text.splitlines()
    lines[i] = fn(lines[i])
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("name, fn, message", [
    ("log.csv", lambda t: _line(t, 3, lambda s: "abc" + s[s.index(","):]),
     "log.csv line 4: time_s is 'abc'; expected a number"),
    ("log.csv", lambda t: _line(t, 5, lambda s: "0.0" + s[s.index(","):]),
     "log.csv line 6: time_s 0 after 0.03; expected strictly increasing times"),
    ("log.csv", lambda t: _line(t, 0, lambda s: s.replace("fz_n", "fq_n")),
     "log.csv line 1: missing fz_n; expected the columns time_s,qref_1"),
    ("log.csv", lambda t: _line(t, 2, lambda s: ",".join(["0.01", ""] + s.split(",")[2:])),
     "log.csv line 3: joints partly empty; expected all of qref_1..q_6 or none"),
    ("log.csv", lambda t: _line(t, 2, lambda s: s + ",1"),
     "log.csv line 3: 21 values; expected 20"),
    ("log.csv", lambda t: _line(t, 1, lambda s: ",".join(["0.0"] + [""] * 15 + s.split(",")[16:])),
     "log.csv line 2: joints empty on the first sample; expected values there"),
    ("seam.csv", lambda t: _line(t, 0, lambda s: "x,y,z"),
     "seam.csv line 1: expected the header 'x_mm,y_mm,z_mm', got 'x,y,z'"),
    ("seam.csv", lambda t: _line(t, 7, lambda s: "1,nan,2"),
     "seam.csv line 8: y_mm is 'nan'; expected a finite number"),
    ("truth.csv", lambda t: _line(t, 4, lambda s: ",".join(s.split(",")[:4] + ["2", "0", "0", "0"])),
     "truth.csv line 5: quaternion norm 2; expected a unit quaternion"),
    ("setup.yaml", lambda t: t + "colour: red\n", "setup.yaml: unknown key 'colour'"),
    ("setup.yaml", lambda t: t.replace("- - [1.0, 0.0, 0.0, 0.0]", "- - [2.0, 0.0, 0.0, 0.0]", 1),
     "setup.yaml: sensors: sensor 1 (T_tool_sensor): expected a rotation (orthonormal, det +1)"),
    ("setup.yaml", lambda t: t.replace("- - [1.0, 0.0, 0.0, 0.0]", "- T_tool_sensor:\n  - [1.0, 0.0, 0.0, 0.0]", 1)
     .replace("  - [0.0, 0.0, 0.0, 1.0]\n", "  - [0.0, 0.0, 0.0, 1.0]\n  latency_s: -0.01\n", 1),
     "setup.yaml: sensors.0.latency_s: expected >= 0.0, got -0.01"),
    ("setup.yaml", lambda t: t.replace("model: puma560", "urdf: nowhere.urdf"),
     "edited/nowhere.urdf: no such URDF file"),
    ("setup.yaml", lambda t: t.replace("particles: 150", "particles: 0"),
     "setup.yaml: filter.particles: expected >= 1, got 0"),
])
def test_bad_log_is_a_one_line_error_naming_file_and_row(recorded, tmp_path, name, fn, message):
    _, _, _, folder = recorded
    bad = _edit(folder, tmp_path, name, fn)
    with pytest.raises((InputFileError, ConfigError)) as exc:      # ConfigError: a bad parameter or URDF
        read_episode_log(bad)
    text = str(exc.value)
    assert "\n" not in text
    assert message in text, text


def test_missing_setup_and_missing_folder(tmp_path):
    with pytest.raises(InputFileError, match="not a folder; expected a recorded episode"):
        read_episode_log(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match="setup.yaml"):
        read_episode_log(tmp_path / "empty")


def test_a_log_with_a_6d_wrench_is_read_and_tracked(recorded, tmp_path):
    _, _, _, folder = recorded
    shutil.copytree(folder, tmp_path / "w")
    lines = (folder / "log.csv").read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        f = line.split(",")
        extra = ["mx_nm", "my_nm", "mz_nm"] if i == 0 else ["1.5", "-2.0", f"{0.01 * i:g}"]
        out.append(",".join(f[:16] + extra + f[16:]))
    (tmp_path / "w" / "log.csv").write_text("\n".join(out) + "\n")
    log = read_episode_log(tmp_path / "w")
    assert log.torque_tool_nm.shape == (60, 3)
    assert log.torque_tool_nm[3] == pytest.approx([1.5, -2.0, 0.04])
    m = track_metrics(track_log(log))
    plain = track_metrics(track_log(read_episode_log(folder)))
    # the default compliance model takes the torque into the joint torques: the particles move otherwise (measured
    # RMSE x/y/z 0.057/0.068/0.078 mm against 0.059/0.075/0.091 without the torque columns: the filter's own spread;
    # tracking 60 and 54 of 60 steps)
    assert m["rmse_mm"] != plain["rmse_mm"]
    assert all(abs(m["rmse_mm"][a] - plain["rmse_mm"][a]) < 0.05 for a in "xyz")
    assert abs(m["status_counts"]["tracking"] - plain["status_counts"]["tracking"]) <= 10
    # without a compliance model the torque changes nothing
    off = {"cell.compliance_rad_per_nm": 0.0}
    log.config = apply_overrides(log.config, off)
    plain_log = read_episode_log(folder)
    plain_log.config = apply_overrides(plain_log.config, off)
    assert track_metrics(track_log(log))["rmse_mm"] == track_metrics(track_log(plain_log))["rmse_mm"]


def test_sensors_may_declare_their_latency_and_readings_their_own_stamps(recorded, tmp_path):
    """setup.yaml: a sensor is a bare 4x4 or {T_tool_sensor, latency_s}; log.csv may carry m{k}_t_s (the reading's
    own time, same clock) that overrides it; a stamp after its row's time is a one-line error."""
    import yaml

    _, _, _, folder = recorded
    d = tmp_path / "lat"
    shutil.copytree(folder, d)
    setup = yaml.safe_load((d / "setup.yaml").read_text())
    setup["sensors"][1] = {"T_tool_sensor": setup["sensors"][1], "latency_s": 0.015}
    (d / "setup.yaml").write_text(yaml.safe_dump(setup))
    log = read_episode_log(d)
    assert log.config.cell.sensors.latency_s == (None, 0.015)
    assert log.reading_time_s is None
    lines = (d / "log.csv").read_text().splitlines()
    head = lines[0].split(",")
    out = [",".join(head[:18] + ["m1_t_s"] + head[18:20] + ["m2_t_s"])]
    for line in lines[1:]:
        f = line.split(",")
        t = float(f[0])
        out.append(",".join(f[:18] + [repr(t - 0.004)] + f[18:20] + [""]))
    (d / "log.csv").write_text("\n".join(out) + "\n")
    log = read_episode_log(d)
    assert log_columns(6, 2, stamps=True) == out[0].split(",")
    np.testing.assert_allclose(log.reading_time_s[:, 0], log.time_s - 0.004)
    assert np.isnan(log.reading_time_s[:, 1]).all()   # empty: the declared latency applies
    tr = track_log(log)
    assert len(tr.status) == 60
    bad = out[:3] + [out[3].replace(repr(float(out[3].split(",")[0]) - 0.004), "99.0", 1)] + out[4:]
    (d / "log.csv").write_text("\n".join(bad) + "\n")
    with pytest.raises(InputFileError, match=r"log\.csv line 4: m1_t_s 99 after time_s 0\.02; expected the "
                                             r"reading's own time, at most the row's$"):
        read_episode_log(d)


def test_a_setup_in_the_layout_before_issue_26_is_mapped_with_a_note(recorded, tmp_path):
    import yaml

    from posekit.seam.frontend.config import LayoutNote

    _, _, _, folder = recorded
    d = tmp_path / "old"
    shutil.copytree(folder, d)
    setup = yaml.safe_load((d / "setup.yaml").read_text())
    comp = setup.pop("compliance_rad_per_nm")
    setup["filter"] = {"particles": 150, "compliance_rad_per_nm": comp, "d0_mm": 2.5, "axis_scale_t": [0.1, 0.3, 1.0],
                       "laser_sigma_mm": 0.05}
    (d / "setup.yaml").write_text(yaml.safe_dump(setup))
    with pytest.warns(LayoutNote, match="the layout before issue 26, mapped: filter.compliance_rad_per_nm -> "
                                        "cell.compliance_rad_per_nm, filter.d0_mm -> profile plateau.d0_mm; 2 old"):
        log = read_episode_log(d)
    assert log.config.cell.compliance_rad_per_nm == comp and log.config.profile.plateau.d0_mm.value == 2.5
