"""Hostile input to the ceiling commands of the next round (issue 13): ``ceiling camera``,
``--camera CAMERA.json`` on calibrate/track/demo, and ``ceiling track`` with its live outputs.

Every bad input is one line ``posekit: error: FILE-or-FLAG: what was wrong; what was expected``,
exit 1, no traceback, and no output file left behind (DESIGN.md "Safe input and output").
"""

import json

import numpy as np
import pytest

from tests.cli_helpers import assert_one_line_error, run_cli

cv2 = pytest.importorskip("cv2")

GOOD_CAMERA = {"K": [[100.0, 0.0, 32.0], [0.0, 100.0, 24.0], [0.0, 0.0, 1.0]], "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
               "image_size": [64, 48], "rms_px": 0.2}


@pytest.fixture()
def scene(tmp_path):
    """Three black 64x48 frames, an identity calibration and a good 64x48 camera file."""
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        cv2.imwrite(str(frames / f"{i:03d}.png"), np.zeros((48, 64, 3), np.uint8))
    cal = tmp_path / "cal.json"
    eye = np.eye(3).tolist()
    cal.write_text(json.dumps({"H_image_world": eye, "H_world_image": eye, "rms_px": 0.1, "rms_world": 0.1}))
    return tmp_path, frames, cal


def _camera(tmp_path, name, **change):
    path = tmp_path / name
    path.write_text(json.dumps({**GOOD_CAMERA, **change}))
    return path


def _raw(tmp_path, name, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def _track(capsys, frames, cal, out, *extra):
    return run_cli(capsys, "ceiling", "track", frames, "--calibration", cal, "--out", out, *extra)


# ------------------------------------------------------------------------ CAMERA.json

CAMERA_CASES = [
    ("k23.json", {"K": [[1, 0, 0], [0, 1, 0]]}, None, "K: expected a 3x3 matrix, got shape (2, 3)"),
    ("negf.json", {"K": [[-100, 0, 32], [0, 100, 24], [0, 0, 1]]}, None,
     "K: focal lengths fx=-100, fy=100; expected both > 0 px"),
    ("skew.json", {"K": [[100, 0, 32], [0, 100, 24], [0, 1, 1]]}, None,
     "K: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"),
    ("dist3.json", {"dist": [0, 0, 0]}, None, "dist: expected 5 coefficients [k1, k2, p1, p2, k3], got 3 values"),
    ("dist8.json", {"dist": [0] * 8}, None, "dist: expected 5 coefficients [k1, k2, p1, p2, k3], got 8 values"),
    ("distbig.json", {"dist": [1e300, 0, 0, 0, 0]}, None,
     "dist: a coefficient of magnitude > 1000; expected a real lens"),
    ("size0.json", {"image_size": [0, 48]}, None, "image_size: 0x48; expected sides between 1 and 100000 px"),
    ("sizestr.json", {"image_size": "64x48"}, None, "image_size: expected [width, height] in px (two integers)"),
    ("kstr.json", {"K": "eye"}, None, "K: expected numbers"),
    ("rms.json", {"rms_px": -1}, None, "rms_px: expected a finite number >= 0, got -1"),
    ("nan.json", None, '{"K": [[NaN, 0, 32], [0, 100, 24], [0, 0, 1]], "dist": [0, 0, 0, 0, 0], '
                       '"image_size": [64, 48]}', "K.0.0: expected a finite number, got nan"),
    ("inf.json", None, '{"K": [[100, 0, 32], [0, 100, 24], [0, 0, 1]], "dist": [Infinity, 0, 0, 0, 0], '
                       '"image_size": [64, 48]}', "dist.0: expected a finite number, got inf"),
    ("empty.json", None, "", "not valid JSON (line 1 column 1: Expecting value)"),
    ("trunc.json", None, '{"K": [[100, 0', "not valid JSON (line 1 column 15: Expecting ',' delimiter)"),
    ("list.json", None, "[1, 2]", "expected a JSON object with keys K, dist, image_size, rms_px"),
    ("nokey.json", None, '{"K": [[100, 0, 32], [0, 100, 24], [0, 0, 1]]}',
     "missing key 'dist'; expected keys K, dist, image_size, rms_px"),
    ("bigint.json", None, '{"image_size": [' + "1" * 400 + ", 48]}",
     "line 1: a number of 400 digits ('111111111111111111111...'); expected at most 30 digits"),
    ("deep.json", None, "[" * 5000 + "]" * 5000, "nested more than 64 levels deep; expected a flat document"),
]


@pytest.mark.parametrize(("name", "change", "text", "message"), CAMERA_CASES, ids=[c[0] for c in CAMERA_CASES])
def test_bad_camera_file_on_track_and_calibrate(capsys, scene, name, change, text, message):
    tmp, frames, cal = scene
    if text is None:
        cam = _camera(tmp, name, **change)
    else:
        cam = tmp / name
        cam.write_text(text)
    out = tmp / "track.csv"
    rc, o, e = _track(capsys, frames, cal, out, "--camera", cam)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {cam}: {message}\n"
    assert not out.exists() and list(tmp.glob(".track.csv.*")) == []
    pts = tmp / "pts.csv"
    pts.write_text("X,Y,u,v\n0,0,10,10\n100,0,50,10\n0,100,10,40\n100,100,50,40\n50,50,30,25\n")
    rc, o, e = run_cli(capsys, "ceiling", "calibrate", pts, "--camera", cam, "--out", tmp / "c2.json")
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {cam}: {message}\n"
    assert not (tmp / "c2.json").exists()


def test_camera_file_encoding_and_size(capsys, scene):
    tmp, frames, cal = scene
    out = tmp / "t.csv"
    u16 = _raw(tmp, "u16.json", json.dumps(GOOD_CAMERA).encode("utf-16"))
    rc, o, e = _track(capsys, frames, cal, out, "--camera", u16)
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: {u16}: UTF-16 (little-endian) text; expected a camera JSON file "
                 "(posekit ceiling camera --out) in UTF-8\n")
    huge = _raw(tmp, "huge.json", b" " * (2 * 2**20) + json.dumps(GOOD_CAMERA).encode())
    rc, o, e = run_cli(capsys, "--max-input-mb", 1, "ceiling", "track", frames, "--calibration", cal, "--out", out,
                       "--camera", huge)
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: {huge}: 2 MiB, above the 1 MiB limit for a camera JSON file (posekit ceiling "
                 "camera --out) (raise it with --max-input-mb)\n")
    assert not out.exists()


def test_four_coefficients_are_the_opencv_model_with_k3_zero(capsys, scene):
    """OpenCV's 4-coefficient model [k1, k2, p1, p2] is accepted as k3 = 0 (not an error)."""
    from posekit.ceiling.camera.lens import load_camera

    tmp, frames, cal = scene
    cam = _camera(tmp, "d4.json", dist=[0.01, -0.002, 0.0, 0.0])
    assert load_camera(cam).dist.tolist() == [0.01, -0.002, 0.0, 0.0, 0.0]
    rc, o, e = _track(capsys, frames, cal, tmp / "t.csv", "--camera", cam, "--frame-rate-hz", 15)
    assert rc == 0, e
    assert (tmp / "t.csv").read_text().splitlines()[0] == ("frame,time_s,x,y,heading_deg,status,std_mm,"
                                                            "std_heading_deg,reason")


def test_camera_of_another_resolution(capsys, scene):
    tmp, frames, cal = scene
    cam = _camera(tmp, "vga.json", image_size=[640, 480])
    rc, o, e = _track(capsys, frames, cal, tmp / "t.csv", "--camera", cam)
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: {frames}: frames are 64x48 px but the camera model is for 640x480 px; "
                 "calibrate the lens at the resolution of the video\n")
    assert not (tmp / "t.csv").exists()


def test_demo_checks_the_camera_before_rendering(capsys, tmp_path):
    """Fixed here: the demo rendered its whole video (seconds) before reading --camera."""
    bad = _camera(tmp_path, "k23.json", K=[[1, 0, 0], [0, 1, 0]])
    out = tmp_path / "demo"
    rc, o, e = run_cli(capsys, "ceiling", "demo", "--camera", bad, "--out", out)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {bad}: K: expected a 3x3 matrix, got shape (2, 3)\n"
    small = _camera(tmp_path, "small.json")
    rc, o, e = run_cli(capsys, "ceiling", "demo", "--camera", small, "--out", out)
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: --camera {small}: the model is for 64x48 px images; the demo renders "
                 "864x480\n")
    assert not out.exists() or list(out.iterdir()) == []


# ------------------------------------------------------------------------ ceiling camera

def test_camera_verb_bad_flags_and_views(capsys, scene):
    tmp, frames, _ = scene
    junk = _raw(tmp, "junk.png", b"not an image")
    out = tmp / "cam.json"
    base = ["ceiling", "camera", junk, "--square-mm", 20, "--out", out]
    for board in ("9by6", "1x6", "9x101", ""):
        rc, o, e = run_cli(capsys, *base, "--board", board)
        assert_one_line_error(rc, o, e)
        assert e == (f"posekit: error: --board: expected the inner corners as COLSxROWS, each 2..100 (e.g. 9x6), "
                     f"got '{board}'\n")
    for square in ("nan", "-1", "0"):
        rc, o, e = run_cli(capsys, "ceiling", "camera", junk, "--board", "9x6", "--square-mm", square, "--out", out)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: --square-mm: expected a number in 0.1..10000 mm, got {square}\n"
    rc, o, e = run_cli(capsys, "ceiling", "camera", junk, junk, junk, "--board", "9x6", "--square-mm", 20,
                       "--out", out)
    assert_one_line_error(rc, o, e)
    from posekit.errors import one_line

    full = (f"lens calibration: the board was found in 0 view(s); expected at least 3 ({junk.name}: cannot decode the "
            f"image; {junk.name}: cannot decode the image; {junk.name}: cannot decode the image) — check --board (inner "
            "corners, COLSxROWS) and that the whole board is in view")
    assert e == f"posekit: error: {one_line(full, 284)}\n"          # the line's 300 characters
    blank = sorted(frames.iterdir())
    rc, o, e = run_cli(capsys, "ceiling", "camera", *blank, "--board", "9x6", "--square-mm", 20, "--out", out)
    assert_one_line_error(rc, o, e)
    assert e.startswith("posekit: error: lens calibration: the board was found in 0 view(s); expected at least 3 (")
    assert "chessboard 9x6 not found" in e and len(e) <= 301
    assert not out.exists()


def test_camera_verb_out_folder_is_refused_before_the_work(capsys, scene):
    """Fixed here: an --out that is a folder was found only after the calibration."""
    tmp, frames, _ = scene
    folder = tmp / "outdir"
    folder.mkdir()
    rc, o, e = run_cli(capsys, "ceiling", "camera", *sorted(frames.iterdir()), "--board", "9x6", "--square-mm", 20,
                       "--out", folder)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: --out {folder}: is a folder; expected a CAMERA.json file name\n"


# ------------------------------------------------------------------------ ceiling track

@pytest.mark.parametrize(("udp", "message"), [
    ("localhost", "--udp localhost: expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)"),
    ("127.0.0.1:99999", "--udp 127.0.0.1:99999: expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)"),
    ("127.0.0.1:0", "--udp 127.0.0.1:0: expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)"),
    ("127.0.0.1:abc", "--udp 127.0.0.1:abc: expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)"),
    ("", "--udp : expected HOST:PORT with a port in 1..65535 (e.g. 127.0.0.1:5005)"),
    ("no-such-host.invalid:5005", "--udp no-such-host.invalid:5005: host 'no-such-host.invalid' does not resolve"),
    ("8.8.8.8:5005", "--udp 8.8.8.8:5005: 8.8.8.8 is not a loopback address; pass --allow-remote to send poses to "
                     "another machine"),
])
def test_udp_target(capsys, scene, udp, message):
    tmp, frames, cal = scene
    out = tmp / "t.csv"
    rc, o, e = _track(capsys, frames, cal, out, "--udp", udp)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: {message}\n"
    assert not out.exists() and list(tmp.glob(".t.csv.*")) == []


def test_remote_udp_with_allow_remote_runs(capsys, scene):
    tmp, frames, cal = scene
    rc, o, e = _track(capsys, frames, cal, tmp / "t.csv", "--udp", "192.0.2.1:5005", "--allow-remote", "--frame-rate-hz", 15)
    assert rc == 0, e
    assert o.startswith("3 frames: 0 ok, 0 suspect, 0 predicted, 3 lost;")


def test_track_outputs_and_flags(capsys, scene):
    tmp, frames, cal = scene
    folder = tmp / "outdir"
    folder.mkdir()
    out = tmp / "t.csv"
    cases = [
        (["--jsonl", folder], f"--jsonl {folder}: is a folder; expected a file name or -"),
        (["--jsonl", tmp / "nope" / "t.jsonl"], f"--jsonl {tmp / 'nope' / 't.jsonl'}: cannot write (No such file "
                                                "or directory)"),
        (["--dots", "blue"], "--dots: expected 'red' or 'red,green', got 'blue' (or 'line' for a laser line)"),
        (["--dots", "red,red", "--robots", "3"], "--dots red,red means two robots; got --robots 3"),
        (["--robots", "9"], "--robots: expected an integer in 1..8, got 9"),
        (["--robots", "2", "--dots", "red,green"],
         "--robots: several robots are tracked with one red dot each (--dots red) and one camera"),
        (["--live", "--loop", "0"], "--loop: expected an integer in 1..1000000, got 0"),
        (["--max-frames", "0"], "--max-frames: expected an integer in 1..1000000000, got 0"),
        (["--frame-rate-hz", "nan"], "--frame-rate-hz: expected a number in 0.01..10000 Hz, got nan"),
        (["--camera", tmp / "missing.json"], f"{tmp / 'missing.json'}: no such file; expected a camera JSON file "
                                             "(posekit ceiling camera --out)"),
    ]
    for extra, message in cases:
        rc, o, e = _track(capsys, frames, cal, out, *extra)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n", extra
        assert not out.exists()
    rc, o, e = _track(capsys, frames, cal, folder)
    assert_one_line_error(rc, o, e)
    assert e == f"posekit: error: --out {folder}: is a folder; expected a CSV file name\n"
    rc, o, e = run_cli(capsys, "ceiling", "track", frames, "--calibration", cal)
    assert_one_line_error(rc, o, e)
    assert e == "posekit: error: no output: give --out TRACK.csv, --jsonl FILE|- or --udp HOST:PORT\n"
    rc, o, e = _track(capsys, frames, cal, out, "--dots", "line", "--line-method", "sobel")
    assert rc == 2 and o == "" and "Traceback" not in e         # a choice argparse rejects: usage error
    assert e.endswith("posekit ceiling track: error: argument --line-method: invalid choice: 'sobel' (choose from "
                      "'moments', 'hough', 'dotted')\n")


@pytest.mark.parametrize("source", ["7", "/dev/video9", "http://127.0.0.1:1/x.mjpg", "rtsp://"])
def test_camera_index_or_stream_that_does_not_open(capsys, scene, source):
    tmp, _, cal = scene
    out = tmp / "t.csv"
    rc, o, e = run_cli(capsys, "ceiling", "track", source, "--calibration", cal, "--out", out, "--max-frames", 2)
    assert_one_line_error(rc, o, e)
    assert e == (f"posekit: error: {source}: cannot open this camera or stream; expected a camera index, "
                 "/dev/videoN, a stream URL (rtsp://, http://) or a video file\n")
    assert not out.exists()


def test_bad_frames_and_folders(capsys, scene):
    tmp, frames, cal = scene
    out = tmp / "t.csv"
    # a frame that does not decode, or whose header claims 10^10 pixels: a 'lost' row, the run goes on
    (frames / "001.png").write_bytes(b"garbage")
    rc, o, e = _track(capsys, frames, cal, out, "--frame-rate-hz", 10)
    assert rc == 0, e
    rows = out.read_text().splitlines()
    assert [r.split(",")[:7] for r in rows[1:]] == [[str(k), f"0.{k}00000", "", "", "", "lost", ""] for k in range(3)]
    assert rows[2].endswith("001.png: cannot decode this file as an image")   # the reason column
    # a frame of another size: a 'lost' row with the reason, the run goes on
    cv2.imwrite(str(frames / "001.png"), np.zeros((40, 30, 3), np.uint8))
    rc, o, e = _track(capsys, frames, cal, out, "--frame-rate-hz", 10)
    assert rc == 0, e
    assert out.read_text().splitlines()[2].endswith(",001.png is 30x40 px but the first frame is 64x48 px (skipped)")
    # a folder with nothing that decodes, an empty folder, a broken video
    bad = tmp / "nothing"
    bad.mkdir()
    (bad / "a.png").write_bytes(b"x")
    empty = tmp / "empty"
    empty.mkdir()
    video = _raw(tmp, "v.mp4", b"\0" * 4000)
    out.unlink()
    for src, message in [
        (bad, f"{bad}: none of the 1 image file(s) decodes ({bad / 'a.png'}: cannot decode this file as an image); "
              "expected a folder of images"),
        (empty, f"{empty}: empty folder; expected images (.png, .jpg, .jpeg, .bmp, .tif, .tiff, .pgm, .ppm, .webp) "
                "sorted by name"),
        (video, f"{video}: cannot read a video frame from this file (not a video OpenCV can decode); expected a "
                "video file or a folder of images"),
        (tmp / "absent", f"{tmp / 'absent'}: no such file or folder; expected a video file or a folder of images"),
    ]:
        rc, o, e = _track(capsys, src, cal, out)
        assert_one_line_error(rc, o, e)
        assert e == f"posekit: error: {message}\n"
        assert not out.exists() and list(tmp.glob(".t.csv.*")) == []
