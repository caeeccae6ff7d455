"""Profile sources and reading options: CSV columns and delimiters, region of interest, metres,
the source classes (files, arrays, simulator, the PKPF socket), and the estimate CLI flags."""

import json
import threading

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.errors import ConfigError, InputFileError, ProfileError
from posekit.profiler import NoiseModel, bundled_gauge, estimate_pose, nominal_pose, render_profiles
from posekit.profiler.stream.reading import (
    ReadOptions,
    apply_roi,
    check_units,
    parse_columns,
    parse_delimiter,
    parse_roi,
    read_profile_file,
    units_hint,
)
from posekit.profiler.stream.socket_source import SocketSource
from posekit.profiler.stream.sources import ArraySource, FileSource, ProfileSource, SimulatedSource
from posekit.profiler.stream.stream_client import SensorClient


@pytest.fixture(scope="module")
def gauge():
    return bundled_gauge("demo-5")


@pytest.fixture(scope="module")
def profile(gauge):
    """One LJ-X8400 profile of demo-5 at the nominal pose, (3200, 2) mm, NaN = no return."""
    return render_profiles(gauge, nominal_pose(gauge), NoiseModel(), rng=0)


def _cell(v) -> str:
    return "" if np.isnan(v) else repr(float(v))


def write_csv(path, header, rows, delimiter=","):
    path.write_text("\n".join([delimiter.join(header)] + [delimiter.join(r) for r in rows]) + "\n")
    return path


def run(capsys, *argv):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


# --- CSV columns and delimiters --------------------------------------------------------------

def test_columns_pick_x_and_z_by_header_name(tmp_path, profile):
    # A vendor export: intensity first, then z and x, with extra spaces and upper case in the header.
    rows = [[str(k % 250), _cell(z), _cell(x)] for k, (x, z) in enumerate(profile)]
    path = write_csv(tmp_path / "scan.csv", ["intensity", " Z ", "X"], rows)
    got = read_profile_file(path, ReadOptions(columns=("x", "z")))
    assert got.shape == (1, 3200, 2)
    np.testing.assert_array_equal(got[0], profile)               # repr round-trips float64 exactly


def test_semicolon_delimiter(tmp_path, profile):
    rows = [[_cell(x), _cell(z), "7"] for x, z in profile]
    path = write_csv(tmp_path / "scan.csv", ["x", "z", "intensity"], rows, ";")
    got = read_profile_file(path, ReadOptions(columns=("x", "z"), delimiter=";"))
    np.testing.assert_array_equal(got[0], profile)
    tab = write_csv(tmp_path / "tab.csv", ["x", "z"], [r[:2] for r in rows], "\t")
    np.testing.assert_array_equal(read_profile_file(tab, ReadOptions(delimiter="\t"))[0], profile)


@pytest.mark.parametrize("text, options, message", [
    ("x,z,intensity\n1,400,9\n", ReadOptions(),
     "line 1: expected header 'x,z', got 'x,z,intensity' (other columns too: pick two by name with --columns x,z)"),
    ("x;z\n1;400\n", ReadOptions(),
     "line 1: expected header 'x,z', got 'x;z' (the cells look separated by ';': give --delimiter ';')"),
    ("a,b\n1,2\n", ReadOptions(), "line 1: expected header 'x,z', got 'a,b'"),
    ("x,height\n1,400\n", ReadOptions(columns=("x", "z")),
     "line 1: no column named 'z' in the header 'x,height'; expected --columns to name two of its columns"),
    ("x,z,x\n1,400,2\n", ReadOptions(columns=("x", "z")),
     "line 1: 2 columns named 'x' in the header 'x,z,x'; expected --columns to name two of its columns"),
    ("x;z;i\n1;400;3\n2;401\n", ReadOptions(columns=("x", "z"), delimiter=";"),
     "line 3: expected 3 values (x,z,i), got 2"),
    ("x;z\n1,5;400\n", ReadOptions(delimiter=";"),
     "line 2: '1,5' is not a number (mm) or empty/nan (a decimal comma? posekit reads a decimal point)"),
    ("x,z\n", ReadOptions(), "no data rows after the header 'x,z'"),
])
def test_csv_errors_are_exact_one_liners(tmp_path, text, options, message):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(InputFileError) as info:
        read_profile_file(path, options)
    assert str(info.value) == f"{path}: {message}"


def test_trailing_delimiter_and_empty_cells(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x;z;\n1.5;400;\n;;\nnan;401;\n")
    got = read_profile_file(path, ReadOptions(delimiter=";"))
    np.testing.assert_array_equal(got[0], [[1.5, 400.0], [np.nan, np.nan], [np.nan, 401.0]])


# --- region of interest ---------------------------------------------------------------------

def test_roi_turns_points_outside_into_no_return(profile):
    got = apply_roi(profile[None], (-20.0, 20.0), (440.0, 446.0))[0]
    x, z = profile[:, 0], profile[:, 1]
    with np.errstate(invalid="ignore"):
        inside = (x >= -20) & (x <= 20) & (z >= 440) & (z <= 446)
    assert np.array_equal(np.isfinite(got[:, 0]), inside) and np.array_equal(np.isfinite(got[:, 1]), inside)
    np.testing.assert_array_equal(got[inside], profile[inside])
    assert 0 < inside.sum() < np.isfinite(x).sum()


def test_roi_removes_clutter_that_breaks_the_estimate(tmp_path, gauge, profile):
    """A fixture in the laser line beside the gauge: the ROI removes it before detection."""
    T = nominal_pose(gauge)
    cluttered = profile.copy()
    first = np.flatnonzero(np.isfinite(profile[:, 0]))[0]
    n = first - 20
    cluttered[:n] = np.column_stack([np.linspace(-150.0, -60.0, n), np.full(n, 380.0)])
    path = tmp_path / "scan.npy"
    np.save(path, cluttered)
    roi = read_profile_file(path, ReadOptions(roi_z_mm=(400.0, 500.0)))
    assert np.isnan(roi[0, :n]).all()
    _, est = estimate_pose(roi[0], gauge)
    assert np.abs(est.t_mm - T[:3, 3]) == pytest.approx(np.zeros(3), abs=1.0)
    assert abs(est.t_mm[0] - T[0, 3]) < 0.05 and abs(est.t_mm[2] - T[2, 3]) < 0.01


# --- metres ---------------------------------------------------------------------------------

def test_a_profile_in_metres_is_refused_with_the_unit(tmp_path, profile):
    path = tmp_path / "metres.npy"
    np.save(path, profile / 1000.0)
    with pytest.raises(InputFileError) as info:
        read_profile_file(path)
    assert str(info.value) == (f"{path}: the profile looks like metres (every |x|, |z| < 2 and it spans 0.11 x "
                               "0.011); posekit expects mm (multiply by 1000)")
    batch = tmp_path / "batch.npz"
    np.savez(batch, profiles=np.stack([profile, profile / 1000.0, profile / 1000.0]))
    with pytest.raises(InputFileError, match=r"profile 1 \(and 1 more\) looks like metres"):
        read_profile_file(batch)
    read_profile_file(path, ReadOptions(check_units=False))      # the check can be turned off
    assert units_hint(profile) is None and units_hint(np.full((5, 2), np.nan)) is None
    # A small part in mm is not metres: spans of 1 mm or more.
    assert units_hint([[0.0, 1.5], [1.2, 1.9]]) is None
    with pytest.raises(ProfileError, match="looks like metres"):
        check_units([[[0.01, 0.4], [0.02, 0.41]]], "array", error=ProfileError)


# --- flags ----------------------------------------------------------------------------------

@pytest.mark.parametrize("call, message", [
    (lambda: parse_columns("x"), "--columns: expected two different header names X,Z (e.g. x,z), got 'x'"),
    (lambda: parse_columns("x,X"), "--columns: expected two different header names X,Z (e.g. x,z), got 'x,X'"),
    (lambda: parse_delimiter(";;"), "--delimiter: expected one character (e.g. ';', or tab), got ';;'"),
    (lambda: parse_roi("5:1", "--roi-x"), "--roi-x: expected A:B in mm with A < B (e.g. -40:40), got '5:1'"),
    (lambda: parse_roi("a:b", "--roi-z"), "--roi-z: expected A:B in mm with A < B (e.g. -40:40), got 'a:b'"),
    (lambda: parse_roi("1:2:3", "--roi-z"), "--roi-z: expected A:B in mm with A < B (e.g. -40:40), got '1:2:3'"),
    (lambda: parse_roi("0:inf", "--roi-x"), "--roi-x: expected A:B in mm with A < B (e.g. -40:40), got '0:inf'"),
])
def test_bad_reading_flags_are_exact_messages(call, message):
    with pytest.raises(ConfigError) as info:
        call()
    assert str(info.value) == message


def test_flag_values():
    assert parse_columns(" X , z ") == ("X", "z") and parse_columns(None) is None
    assert parse_delimiter("tab") == "\t" and parse_delimiter(";") == ";" and parse_delimiter(None) == ","
    assert parse_roi("-40:40", "--roi-x") == (-40.0, 40.0) and parse_roi(None, "--roi-x") is None


def test_cli_estimate_with_columns_delimiter_and_roi(capsys, tmp_path, gauge, profile):
    T = nominal_pose(gauge)
    rows = [[_cell(z), _cell(x), "3"] for x, z in profile]
    path = write_csv(tmp_path / "scan.csv", ["Z", "X", "I"], rows, ";")
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5", "--columns", "X,Z",
                       "--delimiter", ";", "--roi-x", "-60:60", "--roi-z", "400:500")
    assert rc == 0, err
    rec = json.loads(out)
    assert rec["status"] == "ok"
    assert rec["t_mm"] == pytest.approx(list(T[:3, 3]), abs=1.0)
    assert abs(rec["t_mm"][2] - T[2, 3]) < 0.01


@pytest.mark.parametrize("flags, message", [
    (["--columns", "x"], "--columns: expected two different header names X,Z (e.g. x,z), got 'x'"),
    (["--delimiter", "ab"], "--delimiter: expected one character (e.g. ';', or tab), got 'ab'"),
    (["--roi-x", "9:1"], "--roi-x: expected A:B in mm with A < B (e.g. -40:40), got '9:1'"),
    (["--roi-z", "-5"], "--roi-z: expected A:B in mm with A < B (e.g. -40:40), got '-5'"),
])
def test_cli_estimate_bad_reading_flags(capsys, tmp_path, profile, flags, message):
    path = tmp_path / "p.npy"
    np.save(path, profile)
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5", *flags)
    assert (rc, out, err) == (1, "", f"posekit: error: {message}\n")


def test_cli_estimate_metres(capsys, tmp_path, profile):
    path = tmp_path / "m.csv"
    write_csv(path, ["x", "z"], [[_cell(x / 1e3), _cell(z / 1e3)] for x, z in profile])
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", "demo-5")
    assert rc == 1 and out == "" and err.count("\n") == 1
    assert err.startswith(f"posekit: error: {path}: the profile looks like metres (every |x|, |z| < 2")
    assert err.endswith("posekit expects mm (multiply by 1000)\n")


# --- sources --------------------------------------------------------------------------------

def test_array_file_and_simulated_sources(tmp_path, gauge, profile):
    Ts = np.repeat(nominal_pose(gauge)[None], 3, axis=0)
    sim = SimulatedSource(gauge, Ts, rng=1, rate_hz=100.0)
    items = list(sim)
    assert isinstance(sim, ProfileSource) and len(sim) == 3
    assert [t for t, _ in items] == [0.0, 0.01, 0.02] and all(p.shape == (3200, 2) for _, p in items)
    arr = ArraySource(np.stack([p for _, p in items]), t_s=[1.0, 1.5, 1.5])
    assert [t for t, _ in arr] == [1.0, 1.5, 1.5] and isinstance(arr, ProfileSource)
    path = tmp_path / "rec.npz"
    np.savez(path, profiles=np.stack([profile] * 4), t_s=np.array([0.0, 0.012, 0.024, 0.036]))
    src = FileSource(path, ReadOptions(roi_x_mm=(-10.0, 10.0)))
    got = list(src)
    assert [t for t, _ in got] == [0.0, 0.012, 0.024, 0.036]
    assert np.nanmax(np.abs(got[0][1][:, 0])) <= 10.0
    np.savez(path, profiles=np.stack([profile] * 4), t_s=np.array([0.0, 1.0, 0.5, 2.0]))
    with pytest.raises(InputFileError) as info:
        FileSource(path)
    assert str(info.value) == (f"{path}: 't_s' must hold 4 finite, non-decreasing times in s (one per profile), "
                               "got shape (4,)")
    with pytest.raises(ProfileError, match=r"expected profiles of shape \(K, N, 2\) with K >= 1, got \(3200, 2\)"):
        ArraySource(profile)


def test_socket_source_receives_frames_with_the_token(profile):
    source = SocketSource(token="s3cret", end_when_idle_s=0.5)
    host, port = source.start()
    received = []
    reader = threading.Thread(target=lambda: received.extend(source.frames()), daemon=True)
    reader.start()
    with SensorClient(host, port, token="s3cret") as client:
        for k in range(5):
            client.send_profile(k, profile + k, t_sensor_ns=1_000_000 * (k + 1))
    try:
        SensorClient(host, port, token="guess").send_profile(9, profile)
    except (ConfigError, OSError):
        pass
    reader.join(10.0)
    assert not reader.is_alive()
    assert [f.seq for f in received] == [0, 1, 2, 3, 4]
    assert [f.t_sensor_ns for f in received] == [1_000_000 * (k + 1) for k in range(5)]
    np.testing.assert_allclose(received[3].points, profile + 3, rtol=1e-6)   # float32 on the wire
    assert source.counts["frames"] == 5 and source.counts["refused"] == 1


def test_socket_source_is_loopback_only_without_allow_remote():
    with pytest.raises(ConfigError, match="is not a loopback address"):
        SocketSource(("10.1.2.3", 0))
    with pytest.raises(ConfigError, match="allow_remote=True needs a token"):
        SocketSource(("0.0.0.0", 0), allow_remote=True)


def test_socket_source_on_a_taken_port_says_so_in_one_line():
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(ConfigError) as exc:
            SocketSource(("127.0.0.1", port)).start()
    assert str(exc.value) == f"listen address 127.0.0.1:{port}: cannot bind (Address already in use)"
