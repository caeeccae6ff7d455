"""Numeric command-line flags have ranges (issue 11): a value out of its range is one line on
stderr naming the flag, its range and unit and what arrived, exit 1, before anything is read,
allocated or written; text that is no number is a usage error (exit 2).
"""

import argparse

import numpy as np
import pytest

from posekit.ceiling.camera.homography import calibrate
from posekit.ceiling.camera.points import MAX_POINTS, read_points_csv
from posekit.cli._flags import bounded_float, bounded_int, check_flags, check_range
from posekit.cli.main import build_parser
from posekit.errors import CalibrationError, ConfigError
from tests.cli_helpers import assert_one_line_error, run_cli

# --------------------------------------------------------------------------- the helper


def test_bounded_types_parse_in_range_and_mark_the_rest():
    p = argparse.ArgumentParser()
    p.add_argument("--particles", type=bounded_int(1, 1_000_000))
    p.add_argument("--threshold-px", type=bounded_float(0.01, 1e4, "px"))
    p.add_argument("--runs", dest="repeats", type=bounded_int(1, 100, flag="--runs"))
    p.add_argument("--rate", type=bounded_float(0.0, 10.0, "Hz", lo_open=True))
    args = p.parse_args(["--particles", "1e3", "--threshold-px", "0.5", "--runs", "7", "--rate", "10"])
    check_flags(args)
    assert (args.particles, args.threshold_px, args.repeats, args.rate) == (1000, 0.5, 7, 10.0)
    assert type(args.particles) is int
    for argv, message in [
        (["--particles", "1e30"], "--particles: expected an integer in 1..1000000, got 1e30"),
        (["--particles", "0"], "--particles: expected an integer in 1..1000000, got 0"),
        (["--particles", "2.5"], "--particles: expected an integer in 1..1000000, got 2.5"),
        (["--particles", "9" * 5000], "--particles: expected an integer in 1..1000000, got " + "9" * 77 + "..."),
        (["--threshold-px", "1e-300"], "--threshold-px: expected a number in 0.01..10000 px, got 1e-300"),
        (["--threshold-px", "nan"], "--threshold-px: expected a number in 0.01..10000 px, got nan"),
        (["--threshold-px=-inf"], "--threshold-px: expected a number in 0.01..10000 px, got -inf"),
        (["--runs", "101"], "--runs: expected an integer in 1..100, got 101"),
        (["--rate", "0"], "--rate: expected a number > 0 and <= 10 Hz, got 0"),
    ]:
        args = p.parse_args(argv)
        with pytest.raises(ConfigError) as info:
            check_flags(args)
        assert str(info.value) == message
    # an out-of-range value still compares as its number: a verb's older check may come first
    args = p.parse_args(["--particles", "0"])
    assert args.particles == 0 and args.particles < 1 and f"{args.particles}" == "0"
    with pytest.raises(SystemExit) as info:
        p.parse_args(["--particles", "abc"])
    assert info.value.code == 2
    with pytest.raises(ConfigError, match=r"^--tilts-deg: expected numbers in -89..89 deg, got '0:100:10'$"):
        check_range("--tilts-deg", 100.0, -89.0, 89.0, "deg", what="numbers", shown="'0:100:10'")


def test_text_that_is_no_number_is_a_usage_error(capsys, tmp_path):
    rc, _, err = run_cli(capsys, "seam", "simulate", "--particles", "many", "--out", tmp_path / "o")
    assert rc == 2 and "argument --particles: expected an integer in 1..1000000, got 'many'" in err
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- every flag of every verb


def _verbs(parser, path=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _verbs(sub, (*path, name))
    if not any(isinstance(a, argparse._SubParsersAction) for a in parser._actions):
        yield path, parser


#: The smallest valid command line of each verb (files need not exist: flags are checked first).
BASE = {
    ("demo",): ["--out", "{out}"],
    ("profiler", "simulate"): ["--gauge", "demo-5", "--out", "{out}"],
    ("profiler", "study", "corners"): ["--out", "{out}"],
    ("profiler", "study", "noise"): ["--out", "{out}"],
    ("profiler", "study", "limits"): ["--out", "{out}"],
    ("profiler", "loop"): ["--out", "{out}"],
    ("profiler", "accuracy"): [],
    ("ceiling", "calibrate"): ["{tmp}/points.csv", "--out", "{out}.json"],
    ("ceiling", "simulate"): ["--out", "{out}"],
    ("ceiling", "track"): ["{tmp}/video.avi", "--calibration", "{tmp}/cal.json", "--out", "{out}.csv"],
    ("ceiling", "demo"): ["--out", "{out}"],
    ("localcal", "match"): ["{tmp}/a.tum", "{tmp}/b.tum", "--out", "{out}.json"],
    ("localcal", "simulate"): ["--method", "line", "--out", "{out}"],
    ("localcal", "demo"): ["--out", "{out}"],
    ("seam", "simulate"): ["--out", "{out}"],
    ("seam", "demo"): ["--out", "{out}"],
    ("seam", "study"): ["--out", "{out}"],
    ("bench",): ["profiler"],
}
#: Verbs whose flags are checked elsewhere (profiler serve has its own, tested in test_server_hostile).
OTHERS = {("profiler", "serve")}


def _bounded_flags():
    """``(verb, flag, type)`` of every bounded flag (a deprecated alias shares its flag's type)."""
    cases = []
    for path, parser in _verbs(build_parser()):
        if path in OTHERS:
            continue
        for action in parser._actions:
            if (path in BASE and hasattr(action.type, "bounds") and action.option_strings
                    and action.help != argparse.SUPPRESS):
                cases.append((path, action.option_strings[0], action.type))
    return cases


BOUNDED = _bounded_flags()


def test_every_numeric_flag_has_a_range():
    unbounded = []
    for path, parser in _verbs(build_parser()):
        if path in OTHERS:
            continue
        for action in parser._actions:
            if action.type in (int, float) and not action.choices:
                unbounded.append(f"{' '.join(path)} {action.option_strings[0]}")
            if action.help == argparse.SUPPRESS and action.type is not None:      # a deprecated alias
                assert any(a.type is action.type for a in parser._actions if a is not action), action.option_strings
    assert unbounded == []
    assert len(BOUNDED) >= 50


@pytest.mark.parametrize("path, flag, kind", BOUNDED, ids=[f"{' '.join(p)} {f}" for p, f, _ in BOUNDED])
def test_a_flag_out_of_its_range_is_one_line_exit_1_and_nothing_written(capsys, tmp_path, path, flag, kind):
    out = tmp_path / "out"
    base = [a.format(out=out, tmp=tmp_path) for a in BASE[path]]
    lo, hi, unit = kind.bounds
    rc, stdout, err = run_cli(capsys, *path, *base, flag, "1e30")
    assert err == f"posekit: error: {flag}: {kind('1e30').message}\n"
    assert_one_line_error(rc, stdout, err, "expected", "got 1e30", unit)
    assert sorted(p.name for p in tmp_path.iterdir()) == []          # no output, no temporary folder


# --------------------------------------------------------------------------- the crashes of issue 11


@pytest.fixture
def points_csv(tmp_path):
    """A valid 5 x 4 grid of ceiling points and their pixels under a mild homography."""
    H = np.array([[0.2, 0.01, 100.0], [0.005, 0.21, 50.0], [1e-6, 2e-6, 1.0]])
    X, Y = np.meshgrid(np.arange(5) * 600.0, np.arange(4) * 1200.0)
    world = np.column_stack([X.ravel(), Y.ravel()])
    q = np.column_stack([world, np.ones(len(world))]) @ H.T
    image = q[:, :2] / q[:, 2:]
    path = tmp_path / "points.csv"
    path.write_text("X,Y,u,v\n" + "".join(f"{a:.3f},{b:.3f},{c:.4f},{d:.4f}\n" for (a, b), (c, d) in zip(world, image)))
    return path


@pytest.mark.parametrize("flags, needles", [
    (["--seed", "-1"], ["--seed: expected an integer in 0..9223372036854775807, got -1"]),
    (["--threshold-px", "1e-300"], ["--threshold-px: expected a number in 0.01..10000 px, got 1e-300"]),
])
def test_calibrate_flags_that_crashed(capsys, tmp_path, points_csv, flags, needles):
    cal = tmp_path / "cal.json"
    assert run_cli(capsys, "ceiling", "calibrate", points_csv, "--out", cal)[0] == 0       # the points are good
    cal.unlink()
    rc, out, err = run_cli(capsys, "ceiling", "calibrate", points_csv, "--out", cal, *flags)
    assert_one_line_error(rc, out, err, *needles)
    assert not cal.exists()


def test_calibrate_100000_duplicated_points_is_one_line(capsys, tmp_path, points_csv):
    rows = points_csv.read_text().splitlines()
    big = tmp_path / "big.csv"
    big.write_text("\n".join([rows[0], *(rows[1 + k % (len(rows) - 1)] for k in range(100_000))]) + "\n")
    cal = tmp_path / "cal.json"
    rc, out, err = run_cli(capsys, "ceiling", "calibrate", big, "--out", cal)
    assert_one_line_error(rc, out, err, str(big), f"100,001 lines; expected at most {2 * MAX_POINTS + 1000:,} lines "
                                                  "(points, comments and blank lines)")    # counted before parsing
    assert not cal.exists()
    few = tmp_path / "few.csv"                                     # within the limit: the first repeat is named
    few.write_text("\n".join([rows[0], *(rows[1 + k % (len(rows) - 1)] for k in range(5_000))]) + "\n")
    rc, out, err = run_cli(capsys, "ceiling", "calibrate", few, "--out", cal)
    assert_one_line_error(rc, out, err, f"{few} line 22: world point X=0, Y=0 repeats line 2; expected each ceiling "
                                  "point once")
    assert not cal.exists()


def test_read_points_names_a_repeated_pixel(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("X,Y,u,v\n0,0,10,10\n600,0,50,10\n0,1200,10,50\n600,1200,10,10\n")
    with pytest.raises(CalibrationError, match=r"p\.csv line 5: image point u=10, v=10 repeats line 2; expected "
                                               r"distinct pixels \(two ceiling points cannot share one\)$"):
        read_points_csv(path)


def test_calibrate_counts_and_finds_coinciding_points_without_pairing_them():
    world = np.tile([[0.0, 0.0], [1000.0, 0.0], [0.0, 1000.0], [1000.0, 1000.0]], (2500, 1))
    image = np.tile([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]], (2500, 1))
    # 10,000 points, 2,500 copies of each corner: 12.5 million coinciding pairs, named in O(N log N)
    with pytest.raises(CalibrationError, match=r"^homography: world points 0 and 4 coincide at \(0, 0\); "
                                               r"expected distinct points$"):
        calibrate(world, image)
    with pytest.raises(CalibrationError, match=rf"^calibrate: {MAX_POINTS + 1} world points; expected at most "
                                               rf"{MAX_POINTS} "):
        calibrate(np.zeros((MAX_POINTS + 1, 2)), np.zeros((MAX_POINTS + 1, 2)))
    rng = np.random.default_rng(0)                                  # near, not equal: still coinciding
    w = rng.uniform(0, 3000, (50, 2))
    H = np.array([[0.2, 0.01, 100.0], [0.005, 0.21, 50.0], [1e-6, 2e-6, 1.0]])
    q = np.column_stack([w, np.ones(50)]) @ H.T
    i = q[:, :2] / q[:, 2:]
    w[7] = w[3] + 1e-12
    with pytest.raises(CalibrationError, match=r"world points 3 and 7 coincide"):
        calibrate(w, i)


@pytest.mark.parametrize("argv, needles", [
    (["seam", "simulate", "--steps", "15000", "--runs", "70", "--particles", "10"],
     ["--runs 70 × 15000 steps = 1,050,000 episode-steps", "at most 1,000,000"]),
    (["seam", "simulate", "--steps", "15000", "--particles", "10", "--record-particles", "1000"],
     ["--record-particles 1000 × 15000 steps", "at most 133 per step"]),
    (["seam", "demo", "--runs", "400", "--steps", "500"], ["× 6 configurations", "episode-steps"]),
    (["seam", "study", "--runs", "10000", "--episodes", "11"], ["--runs 10000 × --episodes 11 = 110,000 episodes"]),
    (["profiler", "loop", "--runs", "100", "--steps-mm", "1,2,3"], ["closed-loop runs; expected at most 2000"]),
    (["profiler", "loop", "--steps-mm", "1,60"], ["--steps-mm: expected non-zero step sizes in -50..50 mm"]),
    (["profiler", "study", "limits", "--tilts-deg", "-89:89:1e-9"], ["--tilts-deg: '-89:89:1e-9' gives 1.78e+11 values"]),
    (["profiler", "study", "limits", "--widths-mm", "1e30"], ["--widths-mm: expected numbers in 1..1000 mm"]),
    (["profiler", "study", "corners", "--gauges", "10000", "--count", "10000"], ["simulated gauge poses"]),
    (["profiler", "simulate", "--gauge", "demo-5", "--rotation-deg", "4,4,1e9"],
     ["--rotation-deg: expected three numbers in 0..180 deg, got '4,4,1e9'"]),
    (["ceiling", "simulate", "--duration-s", "3600", "--frame-rate-hz", "60"], ["216000 frames; expected at most 54000"]),
    (["ceiling", "calibrate", "p.csv", "--from-image", "r.png", "--grid", "600,1e-9"],
     ["--grid: expected two numbers in 10..100000 mm"]),
    (["localcal", "simulate", "--method", "line", "--start-q-deg", "1e7,0,0,0,0"],
     ["--start-q-deg: expected values in -1e+06..1e+06 deg"]),
    (["seam", "study", "--parameters", "filter.particles=1:1e400"], ["expected finite LOW and HIGH"]),
])
def test_flags_that_together_would_be_absurd(capsys, tmp_path, argv, needles):
    out = tmp_path / "out"
    if argv[:2] == ["ceiling", "calibrate"]:
        (tmp_path / "p.csv").write_text("X,Y,u,v\n0,0,0,0\n1,0,1,0\n0,1,0,1\n1,1,1,1\n")
        argv = [a if a not in ("p.csv",) else str(tmp_path / a) for a in argv]
    rc, stdout, err = run_cli(capsys, *argv, "--out", out)
    assert_one_line_error(rc, stdout, err, *needles)
    assert not out.exists()
