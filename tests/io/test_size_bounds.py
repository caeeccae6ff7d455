"""Size before work (issue 28, deliverable 4): every reader bounds its counts (planes, poses,
points, samples) and checks them before any per-item work, in one line.

A 10 MB gauge YAML with 250,000 planes ran past 60 s; 2,000,000 KITTI poses took 27 s and
1.6 GB before this round. The bounds are lowered with ``set_limits`` here so that the files stay
small; the check is the same at the real bound.
"""

import time

import pytest

from posekit.ceiling.camera.points import read_points_csv
from posekit.errors import CalibrationError, GaugeError, InputFileError
from posekit.io import get_limits, set_limits
from posekit.localcal.registration.formats import read_euroc, read_kitti, read_tum
from posekit.profiler.gauge.model import MAX_RIDGES, load_gauge
from posekit.profiler.stream import reading
from tests.cli_helpers import assert_one_line_error, run_cli


@pytest.fixture
def rows_1000():
    previous = set_limits(rows=1000)
    yield
    set_limits(**vars(previous))


def test_a_gauge_of_250000_planes_is_refused_from_its_size_fast(tmp_path, capsys):
    big = tmp_path / "big.yaml"
    big.write_text("name: big\nplanes:\n" + "".join(f"  - {{normal: [0.1, 1, {i % 7}], offset: {i}.25}}\n"
                                                   for i in range(250_000)))
    assert big.stat().st_size > 10e6
    t0 = time.perf_counter()
    rc, out, err = run_cli(capsys, "profiler", "simulate", "--gauge", big, "--count", 1, "--out", tmp_path / "o")
    elapsed = time.perf_counter() - t0
    assert_one_line_error(rc, out, err, f"{big}: 10.6 MiB, above the 1 MiB limit for a gauge YAML file")
    assert elapsed < 5.0, elapsed                                   # was > 60 s
    small = tmp_path / "many.yaml"                                  # few bytes per plane: refused by count
    small.write_text("name: many\nplanes:\n" + "  - {normal: [0, 0, 1], offset: 1}\n" * (MAX_RIDGES + 2))
    with pytest.raises(GaugeError, match=rf"many.yaml: {MAX_RIDGES + 2} planes; expected at most {MAX_RIDGES + 1} "
                                         rf"\({MAX_RIDGES} ridges\)"):
        load_gauge(small)


@pytest.mark.parametrize("name, line, reader", [
    ("t.tum", "0.1 0 0 0 0 0 0 1\n", read_tum),
    ("k.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n", lambda p: read_kitti(p, 10.0)),
    ("e.csv", "1000000000,0,0,0,1,0,0,0\n", read_euroc),
])
def test_trajectories_are_bounded_by_lines(tmp_path, rows_1000, name, line, reader):
    path = tmp_path / name
    path.write_text(line * 1001)
    with pytest.raises(InputFileError, match=rf"{name}: 1,001 lines; expected at most 1,000 poses \(one per line\) "
                                             r"\(raise it with --max-input-mb\)$"):
        reader(path)


def test_the_fast_path_and_the_line_by_line_reader_agree(tmp_path):
    """KITTI and EuRoC rows are parsed in C when the file is regular (2e6 rows: 27 -> 12 s, 1.6 -> 1.0 GB);
    the line-by-line reader still names the bad line otherwise."""
    k = tmp_path / "k.txt"
    k.write_text("# poses\n" + "".join(f"1 0 0 {0.1 * i:.1f} 0 1 0 0 0 0 1 0\n" for i in range(5)) + "\n")
    traj = read_kitti(k, 10.0)
    assert traj.T[:, 0, 3].tolist() == pytest.approx([0.0, 100.0, 200.0, 300.0, 400.0])
    k.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 x 0 1 0 0 0 0 1 0\n")
    with pytest.raises(InputFileError, match=r"k.txt:2: expected 12 numbers .*found 'x'"):
        read_kitti(k, 10.0)


def test_a_profile_csv_is_bounded_by_its_points(tmp_path, monkeypatch):
    monkeypatch.setattr(reading, "MAX_CSV_POINTS", 100)
    path = tmp_path / "p.csv"
    path.write_text("x,z\n" + "1,400\n" * 101)
    with pytest.raises(InputFileError, match=r"p.csv: 102 lines; expected at most 101 points \(one profile\)$"):
        reading.read_profile_file(path)
    path.write_text("x,z\n" + "1,400\n" * 100)
    assert reading.read_profile_file(path).shape == (1, 100, 2)


def test_calibration_points_are_bounded_by_lines(tmp_path, monkeypatch):
    import posekit.ceiling.camera.points as cal

    monkeypatch.setattr(cal, "MAX_POINTS", 10)
    path = tmp_path / "pts.csv"
    path.write_text("X,Y,u,v\n" + "# a comment\n" * 1100)
    with pytest.raises(CalibrationError, match=r"pts.csv: 1,101 lines; expected at most 1,020 lines"):
        read_points_csv(path)


def test_max_input_mb_raises_the_row_bound(tmp_path, capsys):
    assert get_limits().rows == 2_000_000
    path = tmp_path / "t.tum"
    path.write_text("0.1 0 0 0 0 0 0 1\n" * 10)
    previous = set_limits(rows=5)
    try:
        rc, out, err = run_cli(capsys, "localcal", "match", path, path, "--out", tmp_path / "r.json")
        assert_one_line_error(rc, out, err, "t.tum: 10 lines; expected at most 5 poses")
        rc, out, err = run_cli(capsys, "--max-input-mb", "1", "localcal", "match", path, path, "--out",
                               tmp_path / "r.json")
        assert "10 lines" not in err                  # 1 MiB of text: 8,192 rows allowed
    finally:
        set_limits(**vars(previous))
