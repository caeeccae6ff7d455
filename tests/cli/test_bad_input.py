"""Bad input: one line ``posekit: error: ...`` on stderr, exit 1, no traceback (STYLE.md §5, §7).

The same causes are also checked at the library edge with ``pytest.raises``.
"""

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from posekit.cli.main import main
from posekit.errors import GaugeError, InputFileError, PosekitError, ProfileError
from posekit.profiler.estimate.corners import detect_corners
from posekit.profiler.gauge.model import load_gauge
from posekit.profiler.sensor import NoiseModel
from posekit.profiler.sim.poses import sample_poses
from posekit.profiler.sim.render import render_profiles
from posekit.profiler.stream.reading import read_profiles

GAUGE_DIR = Path(__file__).resolve().parents[2] / "examples" / "gauges"
DEMO5 = GAUGE_DIR / "demo-5.yaml"
BASE = yaml.safe_load(DEMO5.read_text())      # name, planes (6 faces), extent

# Two faces whose normals differ only in y meet in a line along x: no y-component.
FACE_Y_PLUS = {"normal": [0.0, 0.2, 1.0], "offset": 20.0}
FACE_Y_MINUS = {"normal": [0.0, -0.2, 1.0], "offset": 20.0}


# --- helpers --------------------------------------------------------------------------

def run(capsys, *argv):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc, out, err, *needles):
    """Exit 1, one line ``posekit: error: ...`` naming every needle, no traceback."""
    assert rc == 1, err
    assert "Traceback" not in err
    assert err.startswith("posekit: error: "), err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert out == ""
    for needle in needles:
        assert needle in err, f"{needle!r} not in {err!r}"


def gauge_variant(tmp_path, name, edit):
    """demo-5 with ``edit(dict)`` applied, written to ``tmp_path/name``."""
    data = copy.deepcopy(BASE)
    edit(data)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def swap(i, j):
    def edit(d):
        d["planes"][i], d["planes"][j] = d["planes"][j], d["planes"][i]
    return edit


def set_faces(**faces):
    def edit(d):
        for k, face in faces.items():
            d["planes"][int(k[1:])] = face
    return edit


def parallel_faces(d):
    """Face 2 parallel to face 1 (same normal, other offset)."""
    d["planes"][2] = {"normal": list(d["planes"][1]["normal"]), "offset": d["planes"][1]["offset"] + 5.0}


def add_key(d):
    d["colour"] = "red"


def add_plane_key(d):
    d["planes"][0]["colour"] = "red"


def drop_planes(d):
    del d["planes"]


def four_faces(d):
    d["planes"] = d["planes"][:4]


def reverse_faces(d):
    d["planes"] = d["planes"][::-1]


def zero_normal(d):
    d["planes"][2]["normal"] = [0.0, 0.0, 0.0]


def face_away(d):
    d["planes"][3]["normal"] = [0.4, 0.3, -0.8]


def bad_extent(d):
    d["extent"]["x"] = [55.0, -55.0]


def string_offset(d):
    d["planes"][1]["offset"] = "deep"


# (edit, substrings the message must contain)
GAUGE_CASES = {
    "unknown-key": (add_key, ["unknown key 'colour'"]),
    "unknown-plane-key": (add_plane_key, ["unknown key 'planes.0.colour'"]),
    "missing-planes": (drop_planes, ["missing key 'planes'"]),
    "four-faces": (four_faces, ["expected at least 5 faces (4 ridges), got 4"]),
    "parallel-faces": (parallel_faces, ["faces 1 and 2 are parallel"]),
    "ridge-without-y": (set_faces(f1=FACE_Y_PLUS, f2=FACE_Y_MINUS), ["ridge 1 (faces 1/2) has no y-component"]),
    "faces-out-of-order": (swap(1, 3), ["faces do not meet in order"]),
    "faces-reversed": (reverse_faces, ["faces do not meet in order"]),
    "adjacent-faces-swapped": (swap(2, 3), ["gauge 'demo-5'", "ridge"]),
    "zero-normal": (zero_normal, ["face 2 has a zero normal"]),
    "face-away": (face_away, ["face 3 faces away from the sensor"]),
    "bad-extent": (bad_extent, ["extent must be [min, max] with min < max"]),
    "non-numeric-offset": (string_offset, ["key 'planes.1.offset'"]),
}


@pytest.fixture(scope="module")
def good_npz(tmp_path_factory):
    """A valid batch of two demo-5 profiles (so only the gauge can be wrong)."""
    gauge = load_gauge(DEMO5)
    profiles = render_profiles(gauge, sample_poses(gauge, 2, 0), NoiseModel(), 0)
    path = tmp_path_factory.mktemp("good") / "profiles.npz"
    np.savez(path, profiles=profiles)
    return path


@pytest.fixture(scope="module")
def clean_profile():
    """One noise-free demo-5 profile at a fixed pose, and the gauge."""
    gauge = load_gauge(DEMO5)
    return gauge, render_profiles(gauge, sample_poses(gauge, 1, 3)[0], NoiseModel(0.0, 0.0), 3)


# --- CLI: profile files ---------------------------------------------------------------

def write_bytes(data):
    return lambda path: path.write_bytes(data)


def write_text(text):
    return lambda path: path.write_text(text)


def write_npy(arr):
    return lambda path: np.save(path, arr)


def write_npz(**arrays):
    return lambda path: np.savez(path, **arrays)


# file name, how to write it, substrings of the message
INPUT_CASES = {
    "empty-csv": ("p.csv", write_bytes(b""), ["file is empty"]),
    "empty-npy": ("p.npy", write_bytes(b""), ["file is empty"]),
    "empty-npz": ("p.npz", write_bytes(b""), ["file is empty"]),
    "csv-wrong-header": ("p.csv", write_text("a,b\n1,2\n"), ["line 1", "expected header 'x,z'", "'a,b'"]),
    "csv-non-numeric": ("p.csv", write_text("x,z\n1.0,400.0\n2.0,abc\n"), ["line 3", "'abc' is not a number"]),
    "csv-three-columns": ("p.csv", write_text("x,z\n1.0,400.0,7\n"), ["line 2", "expected 2 values"]),
    "csv-header-only": ("p.csv", write_text("x,z\n"), ["no data rows"]),
    "csv-infinite": ("p.csv", write_text("x,z\n1.0,inf\n"), ["line 2", "infinite"]),
    "csv-binary": ("p.csv", write_bytes(b"\xff\xfe\x00\x81garbage"), ["UTF-16 (little-endian) text", "in UTF-8"]),
    "npy-wrong-shape": ("p.npy", write_npy(np.zeros((10, 3))), ["expected an array of shape (N, 2)", "(10, 3)"]),
    "npy-batch": ("p.npy", write_npy(np.zeros((2, 10, 2))), ["(N, 2)", "(2, 10, 2)"]),
    "npy-strings": ("p.npy", write_npy(np.array([["a", "b"]])), ["must hold numbers"]),
    "npy-garbage": ("p.npy", write_bytes(b"not numpy at all"), ["not a NumPy .npy file"]),
    "npz-without-profiles": ("p.npz", write_npz(scan=np.zeros((1, 10, 2))), ["'profiles'", "found scan"]),
    "npz-wrong-shape": ("p.npz", write_npz(profiles=np.zeros((10, 2))), ["'profiles' of shape (K, N, 2)", "(10, 2)"]),
    "npz-no-profile": ("p.npz", write_npz(profiles=np.zeros((0, 10, 2))), ["K = 0"]),
    "npz-infinite": ("p.npz", write_npz(profiles=np.full((1, 10, 2), np.inf)), ["infinite"]),
    "npz-garbage": ("p.npz", write_bytes(b"PK not a zip"), ["not a NumPy .npz archive (no zip header)"]),
    "unknown-suffix": ("p.txt", write_text("x,z\n1,2\n"), ["unknown file type '.txt'", ".csv, .npy or .npz"]),
}


def test_cli_missing_input_file(capsys, tmp_path):
    path = tmp_path / "nowhere.npz"
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", DEMO5)
    assert_one_line_error(rc, out, err, str(path), "no such file")


def test_cli_input_is_a_folder(capsys, tmp_path):
    rc, out, err = run(capsys, "profiler", "estimate", tmp_path, "--gauge", DEMO5)
    assert_one_line_error(rc, out, err, str(tmp_path), "is a folder")


@pytest.mark.parametrize("name, write, needles", INPUT_CASES.values(), ids=INPUT_CASES.keys())
def test_cli_bad_profile_file(capsys, tmp_path, name, write, needles):
    path = tmp_path / name
    write(path)
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", DEMO5)
    assert_one_line_error(rc, out, err, str(path), *needles)


def test_cli_npz_without_profiles_message_is_not_wrapped(capsys, tmp_path):
    path = tmp_path / "p.npz"
    np.savez(path, scan=np.zeros((1, 10, 2)))
    rc, out, err = run(capsys, "profiler", "estimate", path, "--gauge", DEMO5)
    assert_one_line_error(rc, out, err, "'profiles'")
    assert "not a valid .npz file" not in err
    assert err.count(str(path)) == 1


def test_cli_unwritable_out(capsys, tmp_path, good_npz):
    (tmp_path / "a_file").write_text("")
    out_path = tmp_path / "a_file" / "poses.csv"  # its folder is a file
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", DEMO5, "--out", out_path)
    assert_one_line_error(rc, out, err, str(out_path), "cannot write")
    # missing folders of a new file are created, and the file appears whole
    deep = tmp_path / "new" / "folder" / "poses.csv"
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", DEMO5, "--out", deep)
    assert deep.read_text().startswith("index,status,") and not list(deep.parent.glob(".*partial"))


# --- CLI: gauge files -----------------------------------------------------------------

def test_cli_gauge_file_missing(capsys, tmp_path, good_npz):
    path = tmp_path / "missing.yaml"
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", path)
    assert_one_line_error(rc, out, err, str(path), "no such file; expected a gauge YAML file")


def test_cli_gauge_yaml_malformed(capsys, tmp_path, good_npz):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nplanes: [\n  - {normal: [1, 2\n")
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", path)
    assert_one_line_error(rc, out, err, str(path), "not valid YAML")


def test_cli_gauge_yaml_not_a_mapping(capsys, tmp_path, good_npz):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", path)
    assert_one_line_error(rc, out, err, str(path), "expected a mapping", "got list")


@pytest.mark.parametrize("edit, needles", GAUGE_CASES.values(), ids=GAUGE_CASES.keys())
def test_cli_bad_gauge(capsys, tmp_path, good_npz, edit, needles):
    path = gauge_variant(tmp_path, "gauge.yaml", edit)
    rc, out, err = run(capsys, "profiler", "estimate", good_npz, "--gauge", path)
    assert_one_line_error(rc, out, err, str(path), *needles)


@pytest.mark.parametrize("edit, needles", GAUGE_CASES.values(), ids=GAUGE_CASES.keys())
def test_cli_simulate_bad_gauge(capsys, tmp_path, edit, needles):
    path = gauge_variant(tmp_path, "gauge.yaml", edit)
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", path, "--count", 1, "--out", tmp_path / "o")
    assert_one_line_error(rc, out, err, str(path), *needles)
    assert not (tmp_path / "o").exists()


# --- CLI: simulate options ------------------------------------------------------------

SIMULATE_CASES = {
    "count-zero": (["--count", 0], ["--count must be >= 1, got 0"]),
    "count-negative": (["--count", -3], ["--count must be >= 1, got -3"]),
    "noise-negative": (["--noise-um", -1], ["noise", "must be a finite number >= 0"]),
    "noise-x-negative": (["--noise-x-um", -1], ["noise", ">= 0", "-1"]),
    "outliers-too-many": (["--outliers", 0.9], ["<= 0.5", "0.9"]),
    "translation-two-values": (["--translation-mm", "1,2"], ["--translation-mm", "three comma-separated numbers"]),
    "rotation-not-numbers": (["--rotation-deg", "a,b,c"], ["--rotation-deg", "'a,b,c'"]),
    "rotation-negative": (["--rotation-deg", "1,-2,3"], ["rotation", ">= 0"]),
}


@pytest.mark.parametrize("extra, needles", SIMULATE_CASES.values(), ids=SIMULATE_CASES.keys())
def test_cli_simulate_bad_option(capsys, tmp_path, extra, needles):
    out_dir = tmp_path / "sim"
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", DEMO5, "--out", out_dir, *extra)
    assert_one_line_error(rc, out, err, *needles)
    assert not out_dir.exists()


def test_cli_simulate_negative_noise_names_the_flag(capsys, tmp_path):
    rc, out, err = run(capsys, "profiler", "simulate", "--gauge", DEMO5, "--noise-um", -1, "--out", tmp_path / "o")
    assert_one_line_error(rc, out, err, "--noise-um", "-1")


def test_cli_usage_errors_exit_2(capsys, tmp_path, good_npz):
    assert run(capsys, "profiler", "estimate", good_npz)[0] == 2                       # no --gauge
    assert run(capsys, "profiler", "estimate", good_npz, "--gauge", DEMO5, "--method", "svd")[0] == 2
    assert run(capsys, "profiler", "simulate", "--gauge", DEMO5)[0] == 2               # no --out
    assert run(capsys, "profiler", "simulate", "--gauge", DEMO5, "--count", "x", "--out", tmp_path)[0] == 2


# --- library: load_gauge --------------------------------------------------------------

def test_load_gauge_missing(tmp_path):
    with pytest.raises(GaugeError, match=r"missing\.yaml: no such file; expected a gauge YAML file"):
        load_gauge(tmp_path / "missing.yaml")


def test_load_gauge_malformed(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nplanes: [\n  - {normal: [1, 2\n")
    with pytest.raises(GaugeError, match=r"broken\.yaml: not valid YAML at line \d+"):
        load_gauge(path)


@pytest.mark.parametrize("edit, needles", GAUGE_CASES.values(), ids=GAUGE_CASES.keys())
def test_load_gauge_bad(tmp_path, edit, needles):
    path = gauge_variant(tmp_path, "gauge.yaml", edit)
    with pytest.raises(GaugeError) as info:
        load_gauge(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ")
    assert "\n" not in msg
    for needle in needles:
        assert needle in msg


def test_gauge_errors_are_value_errors(tmp_path):
    path = gauge_variant(tmp_path, "gauge.yaml", four_faces)
    with pytest.raises(ValueError):
        load_gauge(path)


def test_load_gauge_parallel_message(tmp_path):
    path = gauge_variant(tmp_path, "gauge.yaml", parallel_faces)
    with pytest.raises(GaugeError, match=r"faces 1 and 2 are parallel \(angle 0\.00 deg, expected >= 2\.0 deg\)"):
        load_gauge(path)


def test_load_gauge_ridge_without_y_message(tmp_path):
    path = gauge_variant(tmp_path, "gauge.yaml", set_faces(f1=FACE_Y_PLUS, f2=FACE_Y_MINUS))
    with pytest.raises(GaugeError, match=r"ridge 1 \(faces 1/2\) has no y-component \(direction \[1\.0, 0\.0, -?0\.0\]\)"):
        load_gauge(path)


def test_load_gauge_unchanged_example_loads():
    assert load_gauge(DEMO5).n_corners == 5


# --- library: read_profiles -----------------------------------------------------------

def test_read_profiles_missing(tmp_path):
    with pytest.raises(InputFileError, match="no such file"):
        read_profiles(tmp_path / "nowhere.csv")


@pytest.mark.parametrize("name, write, needles", INPUT_CASES.values(), ids=INPUT_CASES.keys())
def test_read_profiles_bad(tmp_path, name, write, needles):
    path = tmp_path / name
    write(path)
    with pytest.raises(InputFileError) as info:
        read_profiles(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ")
    for needle in needles:
        assert needle in msg


def test_read_profiles_csv_header_message(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(InputFileError, match=r"line 1: expected header 'x,z', got 'a,b'$"):
        read_profiles(path)


def test_read_profiles_csv_nan_and_empty_cells(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x,z\n1.5,400\nnan,NaN\n2.5,\n,401\n\n")      # a trailing blank line is ignored
    profiles = read_profiles(path)
    assert profiles.shape == (1, 4, 2)
    np.testing.assert_array_equal(profiles[0, 0], [1.5, 400.0])
    assert np.isnan(profiles[0, 1]).all()
    assert profiles[0, 2, 0] == 2.5 and np.isnan(profiles[0, 2, 1])
    assert np.isnan(profiles[0, 3, 0]) and profiles[0, 3, 1] == 401.0


def test_read_profiles_csv_row_of_empty_cells_is_a_point(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x,z\n1.5,400\n,\n2.5,401\n")
    assert read_profiles(path).shape == (1, 3, 2)


def test_read_profiles_csv_line_number_after_empty_row(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("x,z\n,\n1.0,abc\n")
    with pytest.raises(InputFileError, match=r"line 3: 'abc' is not a number"):
        read_profiles(path)


# --- library: detect_corners ----------------------------------------------------------

def test_detect_corners_all_nan():
    with pytest.raises(ProfileError, match=r"^profile has no valid points \(every return is NaN\)$"):
        detect_corners(np.full((3200, 2), np.nan), 5, gauge_name="demo-5")


def test_detect_corners_clean_profile(clean_profile):
    gauge, profile = clean_profile
    assert detect_corners(profile, gauge.n_corners).points.shape == (5, 2)


def test_detect_corners_extra_corner_from_bump(clean_profile):
    """A 5 mm high, 4 mm wide object on face 2 (between corners 1 and 2)."""
    gauge, profile = clean_profile
    corners = detect_corners(profile, gauge.n_corners).points
    x_mid = 0.5 * (corners[1, 0] + corners[2, 0])
    bumped = profile.copy()
    on_bump = np.abs(bumped[:, 0] - x_mid) < 2.0
    assert on_bump.sum() > 20
    bumped[on_bump, 1] -= 5.0                 # z is depth from the sensor: 5 mm closer
    with pytest.raises(ProfileError, match=r"expected 5 corners for gauge 'demo-5', found an extra corner"):
        detect_corners(bumped, gauge.n_corners, gauge_name="demo-5")


def test_detect_corners_cut_off(clean_profile):
    gauge, profile = clean_profile
    cut = profile.copy()
    cut[: int(0.6 * len(cut))] = np.nan
    with pytest.raises(ProfileError, match=r"expected 5 corners for gauge 'demo-5', found \d .*missing corner"):
        detect_corners(cut, gauge.n_corners, gauge_name="demo-5")


def test_detect_corners_too_few_points(clean_profile):
    gauge, profile = clean_profile
    sparse = np.full_like(profile, np.nan)
    valid = np.flatnonzero(np.isfinite(profile[:, 0]))[:10]
    sparse[valid] = profile[valid]
    with pytest.raises(ProfileError, match=r"only 10 valid points"):
        detect_corners(sparse, gauge.n_corners, gauge_name="demo-5")


@pytest.mark.parametrize("profile, pattern", [
    (np.zeros((10, 3)), r"expected shape \(N, 2\)"),
    (np.zeros((0, 2)), r"profile is empty"),
    (np.array([[1.0, np.inf]] * 10), r"infinite values"),
    ([["a", "b"]], r"non-numeric"),
], ids=["wrong-shape", "empty", "infinite", "strings"])
def test_detect_corners_bad_array(profile, pattern):
    with pytest.raises(ProfileError, match=pattern):
        detect_corners(profile, 5)


def test_profile_errors_are_posekit_errors():
    with pytest.raises(PosekitError):
        detect_corners(np.full((100, 2), np.nan), 5)
