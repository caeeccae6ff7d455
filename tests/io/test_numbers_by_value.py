"""Numbers by value (issue 28, deliverables 3 and 9): Unicode digits, underscores and booleans
are not numbers; YAML tags neither coerce nor crash; control characters from a file are shown
escaped; every message is one line of at most 300 characters."""

import pytest

from posekit.ceiling.camera import load_camera
from posekit.ceiling.camera.homography import load_calibration
from posekit.ceiling.camera.points import read_points_csv
from posekit.errors import MAX_MESSAGE, ConfigError, GaugeError, InputFileError, PosekitError, one_line
from posekit.io import number_array, parse_int, parse_number, parse_yaml
from posekit.localcal.registration.formats import read_euroc, read_kitti, read_tum
from posekit.profiler.gauge.model import bundled_gauge_path, load_gauge
from posekit.profiler.stream.reading import read_profile_file
from posekit.robots import bundled_robot_path, load_urdf
from posekit.seam import config_from_dict, load_config
from tests.cli_helpers import assert_one_line_error, run_cli

ARABIC_12 = "\u0661\u0662"          # '١٢': int() and float() read it as 12
FULLWIDTH_5 = "\uff15"              # '５'


@pytest.mark.parametrize("text", [ARABIC_12, FULLWIDTH_5, "1_000", "1e3\u00a0", True, b"12", None])
def test_parse_number_takes_plain_ascii_only(text):
    with pytest.raises(ValueError):
        parse_number(text)
    with pytest.raises(ValueError):
        parse_int(text)


def test_parse_number_reads_what_files_hold():
    assert [parse_number(t) for t in (" -1.5e3 ", "7", "+.5", "1E-3")] == [-1500.0, 7.0, 0.5, 0.001]
    assert parse_number("nan") != parse_number("nan") and parse_number("-inf") == float("-inf")
    assert parse_int(" 42 ") == 42


def test_number_array_refuses_booleans_and_text():
    assert number_array([[1, 2.5], [3, 4]], "f: k", InputFileError).tolist() == [[1.0, 2.5], [3.0, 4.0]]
    for bad, why in [([1, True], "a boolean"), ([[1, "2"]], "str"), ([[1, 2], [3]], "regular array"),
                     ({"a": 1}, "dict")]:
        with pytest.raises(InputFileError, match=f"^f: k: expected numbers.*{why}"):
            number_array(bad, "f: k", InputFileError)
    with pytest.raises(InputFileError, match="finite"):
        number_array([1.0, float("nan")], "f: k", InputFileError, finite=True)


@pytest.mark.parametrize("name, text, reader, message", [
    ("a.tum", "".join(f"{i}.0 0 0 0 0 0 0 1\n" for i in range(3)) + f"{ARABIC_12}.0 0 0 0 0 0 0 1\n", read_tum,
     "a.tum:4: expected 8 numbers 'timestamp tx ty tz qx qy qz qw', found '\u0661\u0662.0'"),
    ("p.csv", "x,z\n" + "".join(f"{i},400\n" for i in range(20)) + f"{FULLWIDTH_5},400\n", read_profile_file,
     "p.csv: line 22: '\\uff15' is not a number (mm) or empty/nan"),
    ("pts.csv", "X,Y,u,v\n0,0,10,10\n1000,0,500,12\n1000,1000,510,480\n0,1000,8,1_0\n", read_points_csv,
     "pts.csv line 5: v is '1_0'; expected a number"),
    ("e.csv", "1000000000,0,0,0,1,0,0,0\n" + f"2000000000,0,{ARABIC_12},0,1,0,0,0\n", read_euroc,
     "e.csv:2: expected at least 8 comma-separated numbers"),
    ("k.txt", f"1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 {FULLWIDTH_5} 0 1 0 0 0 0 1 0\n", lambda p: read_kitti(p, 10.0),
     "k.txt:2: expected 12 numbers"),
])
def test_readers_refuse_unicode_digits(tmp_path, name, text, reader, message):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    with pytest.raises(PosekitError) as err:
        reader(path)
    assert str(err.value).startswith(f"{path}: ".rstrip(" ") if ":" in message.split(" ")[0] else str(path))
    assert message.split(" ", 1)[1] in str(err.value), str(err.value)


def test_booleans_are_not_numbers_in_json_and_yaml(tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text('{"H_image_world": [[true, 0, 0], [0, 1, 0], [0, 0, 1]], "H_world_image": [[1, 0, 0], '
                   '[0, 1, 0], [0, 0, 1]], "rms_px": 0.1, "rms_world": 0.2}')
    with pytest.raises(PosekitError, match=r"'H_image_world' must be a 3x3 matrix of numbers, got \[\[true"):
        load_calibration(cal)
    cam = tmp_path / "cam.json"
    cam.write_text('{"K": [[500, 0, 320], [0, 500, 240], [0, 0, true]], "dist": [0, 0, 0, 0, 0], '
                   '"image_size": [640, 480], "rms_px": 0.2}')
    with pytest.raises(PosekitError, match="K: expected numbers"):
        load_camera(cam)
    gauge = tmp_path / "g.yaml"
    gauge.write_text(bundled_gauge_path("demo-5").read_text().replace("offset: 3.099276411796", "offset: true"))
    with pytest.raises(GaugeError, match=r"key 'planes.1.offset': Value error, expected a number, got bool True"):
        load_gauge(gauge)
    with pytest.raises(ConfigError, match="trajectory.steps: expected a number, got the boolean true"):
        config_from_dict({"trajectory": {"steps": True}}, "cfg")


def test_urdf_numbers_by_value(tmp_path):
    urdf = tmp_path / "arm.urdf"
    text = bundled_robot_path("ur10").read_text()
    first = text.index('xyz="') + len('xyz="')
    urdf.write_text(text[:first] + ARABIC_12 + " " + text[first:])
    with pytest.raises(ConfigError, match=r"arm.urdf: <origin> xyz='\\u0661\\u0662 .*: expected plain decimal numbers"):
        load_urdf(urdf)


@pytest.mark.parametrize("argv, flag", [
    (["profiler", "simulate", "--gauge", "demo-5", "--count", "\u0661", "--out", "x"], "--count"),
    (["profiler", "simulate", "--gauge", "demo-5", "--count", "1", "--noise-um", FULLWIDTH_5, "--out", "x"],
     "--noise-um"),
    (["profiler", "study", "noise", "--noise-um", f"1,{ARABIC_12}"], "--noise-um"),
])
def test_flags_refuse_unicode_digits(capsys, tmp_path, monkeypatch, argv, flag):
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_cli(capsys, *argv)
    assert rc in (1, 2) and out == "" and flag in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


# --- YAML by value -----------------------------------------------------------------------------

@pytest.mark.parametrize("text, message", [
    ("a: !!int 1.5", "f.yaml: line 1: !!int '1.5' is not a valid int"),
    ("a: !!float 'x'", "f.yaml: line 1: !!float 'x' is not a valid float"),
    ("a: !!bool maybe", "f.yaml: line 1: !!bool 'maybe' is not a valid bool"),
    ("a: !!binary aGVsbG8=", "f.yaml: line 1: the YAML tag '!!binary' is not read"),
    ("a: !!timestamp 2001-12-14", "f.yaml: line 1: the YAML tag '!!timestamp' is not read"),
    ("a: !!set {x, y}", "f.yaml: line 1: the YAML tag '!!set' is not read"),
    ("a:\n  - !!omap [x: 1]", "f.yaml: line 2: the YAML tag '!!omap' is not read"),
    ("a: !!python/object/apply:os.system [ls]", "f.yaml: line 1: the YAML tag '!!python/object/apply:os.system'"),
    ("a: !custom 1", "f.yaml: line 1: the YAML tag '!custom' is not read"),
    ("a: !!int " + "9_" * 5000 + "9", "f.yaml: line 1: !!int '9_9_9_9_9_9_9_9_9_9_9...' is not a valid int"),
    ("a: !!int " + "9_" * 100 + "9", "f.yaml: a: an integer of more than 30 digits"),
])
def test_yaml_tags_are_refused_or_validated_in_one_line(text, message):
    with pytest.raises(InputFileError) as err:
        parse_yaml(text, "f.yaml")
    assert str(err.value).startswith(message), str(err.value)


def test_yaml_plain_tags_are_read_as_their_value_and_dates_stay_text():
    assert parse_yaml("a: !!int '12'\nb: !!str 12\nc: !!float 2\nd: 2024-01-01\ne: !!null x", "f") == \
        {"a": 12, "b": "12", "c": 2.0, "d": "2024-01-01", "e": None}


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("offset: 3.099276411796", "offset: !!int 1.5"), "line 9: !!int '1.5' is not a valid int"),
    (lambda t: t.replace("name: demo-5", "name: !!binary ZGVtbw=="), "line 4: the YAML tag '!!binary' is not read"),
])
def test_gauge_file_with_tags(tmp_path, capsys, edit, message):
    gauge = tmp_path / "g.yaml"
    gauge.write_text(edit(bundled_gauge_path("demo-5").read_text()))
    rc, out, err = run_cli(capsys, "profiler", "simulate", "--gauge", gauge, "--count", "1", "--out", tmp_path / "o")
    assert_one_line_error(rc, out, err, f"{gauge}: {message}")


def test_seam_config_with_tags(tmp_path):
    for text, message in [("trajectory:\n  steps: !!int 1.5\n", "line 2: !!int '1.5' is not a valid int"),
                          ("sensors:\n  noise_mm: !!float 'x'\n", "line 2: !!float 'x' is not a valid float"),
                          ("trajectory:\n  steps: !!str twenty\n", "trajectory.steps")]:
        cfg = tmp_path / "c.yaml"
        cfg.write_text(text)
        with pytest.raises(ConfigError) as err:
            load_config(cfg)
        assert message in str(err.value) and "\n" not in str(err.value)


# --- control characters and length ---------------------------------------------------------------

def test_control_characters_of_a_config_value_are_escaped(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text('trajectory:\n  kind: "xy\\e[2J\\e]0;pwned\\a"\n')
    rc, out, err = run_cli(capsys, "seam", "simulate", "--config", cfg, "--out", tmp_path / "o")
    assert_one_line_error(rc, out, err, "\\x1b[2J\\x1b]0;pwned\\x07")
    assert "\x1b" not in err and "\x07" not in err


def test_one_line_shortens_and_escapes():
    msg = one_line("f.yaml: " + "/very/long/path/" * 40 + "file.csv: line 3: bad\nvalue\x1b[31m; expected x")
    assert len(msg) <= MAX_MESSAGE and "\n" not in msg and "\x1b" not in msg and msg.endswith("expected x")
    assert "file.csv: line 3: bad value\\x1b[31m" in msg
    assert str(PosekitError("x" * 5000)).__len__() <= MAX_MESSAGE
