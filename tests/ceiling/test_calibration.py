"""Ceiling calibration: homography from points, JSON and CSV files, grid finder, CLI verb."""

import argparse
import json
import re
import sys

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from posekit.ceiling.camera.grid import CeilingGrid, find_grid_corners
from posekit.ceiling.camera.homography import Calibration, calibrate, load_calibration
from posekit.ceiling.camera.points import read_points_csv, write_points_csv
from posekit.cli.ceiling_calibrate import add_calibrate_parser
from posekit.errors import CalibrationError, PosekitError
from posekit.geometry import apply_homography, normalize_homography
from tests.ceiling.cli_harness import look_at

DESIGN_KEYS = ["H_image_world", "H_world_image", "rms_px", "rms_world"]
SEED_WORLD = np.array([[1200.0, 1200.0], [4800.0, 1200.0], [4800.0, 3600.0], [1200.0, 3600.0]])


def camera_homography(C=(2500.0, -800.0, 2300.0), target=(3400.0, 2000.0, 0.0), f=560.0, size=(864, 480)):
    """H_image_world (mm -> px) of a pinhole camera at C (Z: mm below the ceiling) looking at target."""
    K = np.array([[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2], [0, 0, 1.0]])
    R_cam_world, t = look_at(C, target)
    return normalize_homography(K @ np.c_[R_cam_world[:, 0], R_cam_world[:, 1], t])


def render_ceiling(H, size=(864, 480), extent=(-4000, 10000, -1200, 9000), mm_per_texel=2.5,
                   spacing=(600.0, 1200.0), bar_mm=15.0, contrast=0.25, noise=2.0, blur=0.6, seed=0):
    """8-bit image of a tiled ceiling: T-bars `bar_mm` wide, `contrast` darker than the speckled
    tiles, seen through H_image_world, supersampled 4x4, blurred, lit unevenly, with noise."""
    rng = np.random.default_rng(seed)
    x0, x1, y0, y1 = extent
    nx, ny = int((x1 - x0) / mm_per_texel), int((y1 - y0) / mm_per_texel)

    def coverage(n, start, sp):                # fraction of each texel [a, a + s) inside a bar
        a = start + mm_per_texel * np.arange(n)
        c = np.round((a + 0.5 * mm_per_texel) / sp) * sp
        overlap = np.minimum(a + mm_per_texel, c + bar_mm / 2) - np.maximum(a, c - bar_mm / 2)
        return np.clip(overlap, 0, None) / mm_per_texel

    bars = 1 - (1 - coverage(nx, x0, spacing[0])[None, :]) * (1 - coverage(ny, y0, spacing[1])[:, None])
    tiles = 200 + cv2.GaussianBlur(rng.normal(0, 6, (ny, nx)).astype(np.float32), (0, 0), 2)
    texture = (tiles * (1 - contrast * bars)).astype(np.float32)
    H_world_texture = np.array([[mm_per_texel, 0, x0 + 0.5 * mm_per_texel],
                                [0, mm_per_texel, y0 + 0.5 * mm_per_texel], [0, 0, 1]])
    ss = 4                                      # pixel u of the image is (4u + 1.5) of the 4x one
    A = np.array([[ss, 0, (ss - 1) / 2], [0, ss, (ss - 1) / 2], [0, 0, 1.0]])
    w, h = size
    big = cv2.warpPerspective(texture, A @ H @ H_world_texture, (w * ss, h * ss), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=120)
    img = cv2.GaussianBlur(cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA), (0, 0), blur)
    uu, vv = np.meshgrid(np.arange(w), np.arange(h))
    img = img * (0.75 + 0.35 * uu / w - 0.1 * vv / h) + rng.normal(0, noise, (h, w))
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def scene():
    H = camera_homography()
    return H, render_ceiling(H)


@pytest.fixture(scope="module")
def points():
    """18 grid corners (world mm, image px) with 0.3 px click noise, as in the paper."""
    H = camera_homography()
    gx, gy = np.meshgrid([600.0, 1800.0, 3000.0, 4200.0, 5400.0, 6600.0], [1200.0, 2400.0, 3600.0])
    world = np.c_[gx.ravel(), gy.ravel()]
    image = apply_homography(H, world) + np.random.default_rng(5).normal(0, 0.3, world.shape)
    return H, world, image


def write(path, text):
    path.write_text(text)
    return path


def one_line(exc_info):
    msg = str(exc_info.value)
    assert "\n" not in msg
    return msg


# --------------------------------------------------------------------------- calibrate
def test_calibrate_exact_points_and_round_trips(points):
    H, world, _ = points
    image = apply_homography(H, world)
    cal = calibrate(world, image)
    assert cal.rms_px < 1e-9 and cal.rms_world < 1e-6
    assert cal.inliers.all() and cal.n_points == 18
    assert cal.H_image_world[2, 2] == 1.0 and cal.H_world_image[2, 2] == 1.0
    assert_allclose(cal.H_image_world, H, rtol=1e-8, atol=1e-12)
    assert_allclose(cal.image_to_world(cal.world_to_image(world)), world, atol=1e-7)
    assert_allclose(cal.world_to_image(world[3]), image[3], atol=1e-9)           # a single point (2,)
    four = calibrate(world[[0, 5, 12, 17]], image[[0, 5, 12, 17]])               # minimal: no RANSAC
    assert_allclose(four.world_to_image(world), image, atol=1e-8)


def test_calibrate_rejects_a_mis_clicked_point(points):
    _, world, image = points
    image = image.copy()
    image[7] += [9.0, 12.0]
    cal = calibrate(world, image, rng=1)
    assert_array_equal(np.flatnonzero(~cal.inliers), [7])
    assert cal.rms_px < 0.5
    no_ransac = calibrate(world, image, ransac=False)
    assert no_ransac.inliers.all() and no_ransac.rms_px > 2.0
    dlt_only = calibrate(world, image, ransac=True, refine=False, rng=1)
    assert dlt_only.rms_px >= cal.rms_px - 1e-12


def test_calibrate_degenerate_points():
    line = np.c_[np.arange(6.0) * 600, np.zeros(6)]
    with pytest.raises(CalibrationError, match=re.escape(
            "homography: all 6 world points lie on one line (or within 0.1 % of one)")):
        calibrate(line, np.c_[np.arange(6.0), np.arange(6.0) ** 2])


# --------------------------------------------------------------------------- JSON
def test_json_round_trip_has_the_design_keys(points, tmp_path):
    _, world, image = points
    cal = calibrate(world, image)
    path = tmp_path / "cal.json"
    cal.to_json(path)
    data = json.loads(path.read_text())
    assert list(data)[:4] == DESIGN_KEYS
    assert data["n_points"] == 18 and data["inliers"] == [True] * 18
    back = load_calibration(path)
    assert_array_equal(back.H_image_world, cal.H_image_world)
    assert_array_equal(back.H_world_image, cal.H_world_image)
    assert (back.rms_px, back.rms_world, back.n_points) == (cal.rms_px, cal.rms_world, 18)
    assert_array_equal(back.inliers, cal.inliers)
    minimal = {k: data[k] for k in DESIGN_KEYS}                       # extra keys are optional
    only = load_calibration(write(tmp_path / "min.json", json.dumps(minimal)))
    assert only.inliers is None and only.n_points is None


def bad_json_cases(good):
    def edit(**changes):
        d = dict(good)
        for k, v in changes.items():
            if v is KeyError:
                d.pop(k)
            else:
                d[k] = v
        return json.dumps(d)

    singular = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]
    return [
        (edit(H_world_image=KeyError),
         "missing key 'H_world_image'; expected the keys H_image_world, H_world_image, rms_px, rms_world"),
        (edit(H_image_world=[[1, 0, 0], [0, 1, 0]]),
         "'H_image_world' must be a 3x3 matrix of numbers, got shape (2, 3)"),
        (edit(H_image_world=[[1, 0], [0, 1, 0], [0, 0, 1]]), "'H_image_world' must be a 3x3 matrix of numbers"),
        (edit(H_world_image="identity"), "'H_world_image' must be a 3x3 matrix of numbers, got \"identity\""),
        (edit(rms_px=float("nan")), "rms_px: expected a finite number, got nan"),
        (edit(rms_world=-1.0), "'rms_world' must be a finite number >= 0, got -1.0"),
        (edit(H_image_world=[[1, 0, 0], [0, float("nan"), 0], [0, 0, 1]]),
         "H_image_world.1.1: expected a finite number, got nan"),
        (edit(H_image_world=singular), "'H_image_world' is singular; expected an invertible homography"),
        (edit(H_world_image=np.eye(3).tolist()), "'H_world_image' is not the inverse of 'H_image_world'"),
        (edit(inliers=[True, "yes"]), "'inliers' must be a list of true/false, one per point"),
        ("[1, 2]", "expected a JSON object with the keys H_image_world, H_world_image, rms_px, rms_world"),
        ('{"H_image_world": [[1, 0, 0]', "not valid JSON (line 1 column 29: Expecting ',' delimiter)"),
    ]


def test_bad_calibration_files_name_the_file_and_key(points, tmp_path):
    _, world, image = points
    calibrate(world, image).to_json(tmp_path / "good.json")
    good = json.loads((tmp_path / "good.json").read_text())
    for k, (text, message) in enumerate(bad_json_cases(good)):
        path = write(tmp_path / f"bad{k}.json", text)
        with pytest.raises(CalibrationError) as exc:
            load_calibration(path)
        msg = one_line(exc)
        assert msg.startswith(f"{path}: ") and message in msg, (msg, message)
    with pytest.raises(CalibrationError, match="nope.json: no such file; expected a calibration JSON file"):
        load_calibration(tmp_path / "nope.json")


# --------------------------------------------------------------------------- CSV
def test_points_csv_round_trip(points, tmp_path):
    _, world, image = points
    path = tmp_path / "points.csv"
    write_points_csv(path, world, image)
    pts = read_points_csv(path)
    assert_allclose(pts.world_xy, world)
    assert_allclose(pts.image_uv, image, atol=5e-5)
    assert_array_equal(pts.lines, np.arange(2, 20))
    text = ("# clicked on 2024-05-01\nX, Y, u, v\n\n0,0,10,20\n600,0,110.5,21\n# skipped\n"
            "600,1200,108,140\n0,1200,9,139\n")
    pts = read_points_csv(write(tmp_path / "commented.csv", text))
    assert_array_equal(pts.lines, [4, 5, 7, 8])
    assert_array_equal(pts.image_uv[1], [110.5, 21.0])


BAD_CSV = [
    ("x,y,u,v\n0,0,1,1\n", "line 1: expected the header 'X,Y,u,v', got 'x,y,u,v'"),
    ("X,Y,u,v\n0,0,1,1\n1,0,2,1\n1,a,2,2\n0,1,1,2\n", "line 4: Y is 'a'; expected a number"),
    ("X,Y,u,v\n0,0,1,1\n1,0,2\n", "line 3: expected 4 values X,Y,u,v, got 3 ('1,0,2')"),
    ("X,Y,u,v\n0,0,1,inf\n", "line 2: v is 'inf'; expected a finite number"),
    ("X,Y,u,v\n0,0,1,1\n1,0,2,1\n1,1,2,2\n", ": 3 calibration points; a homography needs at least 4"),
    ("", ": file is empty; expected the header 'X,Y,u,v' and one point per line"),
]


@pytest.mark.parametrize("text, message", BAD_CSV)
def test_bad_points_csv_names_file_and_line(tmp_path, text, message):
    path = write(tmp_path / "points.csv", text)
    with pytest.raises(CalibrationError) as exc:
        read_points_csv(path)
    msg = one_line(exc)
    assert msg.startswith(str(path)) and message in msg, msg


# --------------------------------------------------------------------------- grid finder
def test_grid_finder_finds_every_crossing_within_half_a_pixel(scene):
    H, img = scene
    seed_image = apply_homography(H, SEED_WORLD) + np.random.default_rng(2).uniform(-5, 5, (4, 2))
    uv, world = find_grid_corners(img, CeilingGrid(), seed_world=SEED_WORLD, seed_image=seed_image)
    assert len(uv) >= 40
    err = np.linalg.norm(uv - apply_homography(H, world), axis=1)
    assert err.max() < 0.5, err.max()
    assert np.sqrt(np.mean(err**2)) < 0.15
    assert np.all(np.mod(world, [600.0, 1200.0]) == 0)
    cal = calibrate(world, uv)
    assert cal.rms_px < 0.5 and cal.inliers.all()
    truth = apply_homography(H, world)
    assert np.abs(cal.world_to_image(world) - truth).max() < 0.2
    # The same from an approximate homography, and from a BGR image restricted to a rectangle.
    H_rough = H @ np.array([[1.002, 0.001, 4.0], [0.0, 0.998, -3.0], [0.0, 0.0, 1.0]])
    uv2, world2 = find_grid_corners(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR), initial_H=H_rough,
                                    bounds_mm=(0, 4000, 0, 4000))
    assert len(uv2) >= 9 and world2.max() <= 4000
    assert np.linalg.norm(uv2 - apply_homography(H, world2), axis=1).max() < 0.5


def test_grid_finder_light_bars_and_errors(scene):
    H, img = scene
    uv, world = find_grid_corners(255 - img, initial_H=H, polarity="light")
    assert len(uv) >= 40
    assert np.linalg.norm(uv - apply_homography(H, world), axis=1).max() < 0.5
    with pytest.raises(CalibrationError, match="give either initial_H or seed_world and seed_image"):
        find_grid_corners(img)
    with pytest.raises(CalibrationError, match=r"^find_grid_corners: found \d+ grid crossings within 10 px"):
        find_grid_corners(np.full_like(img, 128), initial_H=H)
    with pytest.raises(CalibrationError, match="ceiling grid: bar width must be > 0"):
        CeilingGrid(bar_width_mm=0.0)


# --------------------------------------------------------------------------- CLI verb
def run_cli(capsys, *argv):
    """A tiny harness like posekit's main: parse, run, PosekitError -> one line and exit 1."""
    parser = argparse.ArgumentParser(prog="posekit ceiling")
    add_calibrate_parser(parser.add_subparsers(dest="verb", required=True))
    args = parser.parse_args([str(a) for a in argv])
    capsys.readouterr()
    try:
        rc = args.func(args)
    except PosekitError as exc:
        print(f"posekit: error: {exc}", file=sys.stderr)
        rc = 1
    return rc, *capsys.readouterr()


def test_cli_calibrate_writes_the_design_keys(points, tmp_path, capsys):
    _, world, image = points
    image = image.copy()
    image[4] += [0.0, 25.0]
    csv = tmp_path / "points.csv"
    write_points_csv(csv, world, image)
    out = tmp_path / "cal.json"
    rc, stdout, stderr = run_cli(capsys, "calibrate", csv, "--out", out)
    assert rc == 0, stderr
    assert list(json.loads(out.read_text()))[:4] == DESIGN_KEYS
    assert "calibrated from 17 of 18 points" in stdout and "line 6: X=5400 Y=1200" in stdout
    assert re.search(r"rms \d\.\d{3} px in the image, \d+\.\d{3} world units \(mm\)", stdout)
    rc, stdout, _ = run_cli(capsys, "calibrate", csv, "--out", out, "--no-ransac", "--no-refine")
    assert rc == 0 and "calibrated from 18 of 18 points (DLT only, no lens model)" in stdout
    assert isinstance(load_calibration(out), Calibration)
    rc, _, stderr = run_cli(capsys, "calibrate", tmp_path / "missing.csv", "--out", out)
    assert rc == 1 and stderr.count("\n") == 1 and "missing.csv: no such file" in stderr


def test_cli_calibrate_from_image(scene, tmp_path, capsys):
    H, img = scene
    ref = tmp_path / "ref.png"
    cv2.imwrite(str(ref), img)
    seeds = tmp_path / "seeds.csv"
    write_points_csv(seeds, SEED_WORLD, apply_homography(H, SEED_WORLD) + [[3, -2], [-4, 1], [2, 3], [-1, -3]])
    out, found = tmp_path / "cal.json", tmp_path / "found.csv"
    rc, stdout, stderr = run_cli(capsys, "calibrate", seeds, "--out", out, "--from-image", ref,
                                 "--grid", "600,1200", "--write-points", found)
    assert rc == 0, stderr
    cal = load_calibration(out)
    assert cal.rms_px < 0.5 and cal.n_points >= 40
    assert len(read_points_csv(found).world_xy) == cal.n_points
    assert re.search(r"found \d+ grid crossings", stdout)
    rc, _, stderr = run_cli(capsys, "calibrate", seeds, "--out", out, "--from-image", tmp_path / "nope.png")
    assert rc == 1 and "nope.png: no such file; expected an image file" in stderr
    rc, _, stderr = run_cli(capsys, "calibrate", seeds, "--out", out, "--from-image", ref, "--grid", "600")
    assert rc == 1 and "--grid: expected two comma-separated numbers, got '600'" in stderr
