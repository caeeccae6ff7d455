"""Design studies (Table I, Fig. 3, Fig. 4): values that make sense, files that exist.

The studies run in this process (scheduler 'serial'); tests/test_sweep.py checks that a
cluster gives the same numbers.
"""

import argparse
import csv
import math
import re

import numpy as np
import pytest
from scipy import stats

from posekit.cli.profiler_study import add_study_parser, parse_numbers
from posekit.errors import ConfigError, PosekitError
from posekit.geometry import matrix_from_rotation_vector
from posekit.profiler.gauge.model import bundled_gauge
from posekit.profiler.studies.study import (
    GAP_COLUMNS,
    PAPER_TABLE1,
    TABLE1_COLUMNS,
    CornersConfig,
    corners_study,
    ridge_direction_error,
)
from posekit.profiler.studies.study_limits import (
    LimitsConfig,
    limits_study,
    range_summary,
    tilt_summary,
)
from posekit.profiler.studies.study_noise import NoiseConfig, noise_study
from posekit.profiler.studies.study_report import write_report

SERIAL = "serial"


def _read_csv(path):
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return reader.fieldnames, list(reader)


def _check_report(out):
    """report.html exists, links and embeds every PNG, and every PNG is a PNG."""
    text = (out / "report.html").read_text()
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs
    for name in pngs:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f'href="{name}"' in text and f'alt="{name}"' in text
    assert text.count('src="data:image/png;base64,') == len(pngs)
    return text


@pytest.fixture(scope="module")
def corners_small():
    return corners_study(CornersConfig(corners=(4, 5), gauges=(2, 3), poses=10, seed=3), scheduler=SERIAL)


@pytest.mark.slow
def test_corners_study_table1(corners_small, tmp_path):
    write_report(corners_small, tmp_path)
    header, rows = _read_csv(tmp_path / "table1.csv")
    assert tuple(header) == TABLE1_COLUMNS
    assert [(int(r["n"]), int(r["m"]), r["method"]) for r in rows] == [
        (n, m, method) for method in ("cf", "mle") for n in (4, 5) for m in (2, 3)]
    row = {(r["method"], int(r["n"]), int(r["m"])): r for r in rows}
    for m in (2, 3):
        cf4 = row[("cf", 4, m)]                                       # the paper's '-': CF needs n >= 5
        assert int(cf4["failures"]) == 10 * m and math.isnan(float(cf4["reproj_mean_um"]))
        for n in (4, 5):
            mle = row[("mle", n, m)]
            # a residual and an error exist (5 µm of noise), and no pose is lost: each is a
            # finite, positive number; how large is the noise study's (it scales with the noise)
            assert float(mle["reproj_mean_um"]) > 0 and float(mle["reproj_std_um"]) > 0
            assert int(mle["failures"]) == 0 and np.isfinite(float(mle["t_err_mean_um"]))
        cf5, mle5 = row[("cf", 5, m)], row[("mle", 5, m)]
        assert float(mle5["t_err_mean_um"]) < float(cf5["t_err_mean_um"])
        assert float(mle5["rot_err_mean_deg"]) < float(cf5["rot_err_mean_deg"])
        assert float(mle5["reproj_mean_um"]) < 0.2 * float(cf5["reproj_mean_um"])
        # the paper's eq. (17) × 10³: CF-Opt below 1 (its '*'), CF of the paper's order (10/10), far
        # below the same estimates' reprojection error in µm
        for n in (4, 5):
            assert 0 < float(row[("mle", n, m)]["eq17_mean_um_per_mm"]) < 1.0           # the paper's '*'
        assert float(mle5["eq17_mean_um_per_mm"]) < float(cf5["eq17_mean_um_per_mm"])
        assert float(cf5["eq17_mean_um_per_mm"]) < 0.3 * float(cf5["reproj_mean_um"])
        assert math.isnan(float(row[("cf", 4, m)]["eq17_mean_um_per_mm"]))
    # nested subsets: the m = 2 row is the first 2 gauges of the m = 3 sample
    s = corners_small.samples[5]
    assert s["status"].shape == (3, 10, 2)
    ok = np.isin(s["status"][:2, :, 1], (0, 3))
    assert float(row[("mle", 5, 2)]["reproj_mean_um"]) == pytest.approx(s["reproj_um"][:2, :, 1][ok].mean(), rel=1e-5)
    text = _check_report(tmp_path)
    assert {"table1_reprojection.png", "table1_pose_error.png"} <= {p.name for p in tmp_path.glob("*.png")}
    assert "<th>ours m=3</th>" in text and "<th>paper m=150</th>" in text   # the paper's Table I beside ours
    assert f"<td>{PAPER_TABLE1[('cf', 5)][1]}</td>" in text
    assert "<td>eq. (17) × 10³</td>" in text and "<td>reprojection (µm)</td>" in text
    assert "the closed form needs at least 5 corners" in text
    # the closed-form gap: measured, with F's origin moved to the stand-off as one of its causes
    header, gap = _read_csv(tmp_path / "table1_gap.csv")
    assert tuple(header) == GAP_COLUMNS and [int(r["n"]) for r in gap] == [4, 5]
    g5 = gap[1]
    assert g5["paper_cf"] == PAPER_TABLE1[("cf", 5)][-1]
    assert float(g5["standoff_reproj_mean_um"]) < 0.3 * float(g5["reproj_mean_um"])   # a smaller residual ...
    assert float(g5["standoff_t_err_mean_um"]) > 0.5 * float(g5["t_err_mean_um"])     # ... not a better pose
    assert float(g5["eq17_mid_median_um_per_mm"]) > float(g5["eq17_mean_um_per_mm"])  # q mid-block: |y| → 0
    assert float(g5["corner_std_um"]) > 0
    assert "<b>The metric.</b>" in text and "<b>Where F's origin is.</b>" in text


def test_ridge_direction_error_hand_case():
    """Eq. (17) by hand: a corner 10 µm off its ridge, 5 mm from q along the ridge, gives
    ‖s - ŝ‖ = 0.010 / 5 = 0.002 whatever the rotation about G's y (which keeps the laser plane)."""
    g = bundled_gauge("demo-5")
    for angle_deg in (0.0, 30.0):
        T = np.eye(4)
        T[:3, :3] = matrix_from_rotation_vector([0.0, np.radians(angle_deg), 0.0])
        T[1, 3] = 5.0                                       # the laser plane is G's y = 5 mm
        p_G = g.ridge_q + 5.0 * g.ridge_s                   # where the ridges cross it
        c = ((p_G - T[:3, 3]) @ T[:3, :3])[:, [0, 2]]       # exact corners (x, z) in F
        np.testing.assert_allclose(ridge_direction_error(T, c, g), 0.0, atol=1e-12)
        c[2, 0] += 0.010                                    # corner 2: 10 µm along F's x
        np.testing.assert_allclose(ridge_direction_error(T, c, g), [0, 0, 0.002, 0, 0], atol=1e-12)
        # q at the block's end, y = -20: 25 mm from the corner
        np.testing.assert_allclose(ridge_direction_error(T, c, g, y_q=-20.0)[2], 0.010 / 25.0, rtol=1e-12)
    # batched, and a corner in the plane of q (y = y_q): eq. (17) divides by zero
    Ts = np.stack([T, T])
    Ts[1, 1, 3] = 0.0
    c0 = ((g.ridge_q - Ts[1, :3, 3]) @ Ts[1, :3, :3])[:, [0, 2]]
    out = ridge_direction_error(Ts, np.stack([c, c0]), g)
    assert out.shape == (2, 5) and out[0, 2] == pytest.approx(0.002) and not np.any(np.isfinite(out[1]))


def test_corners_study_same_gauges_as_noise_study(corners_small):
    """The noise study draws the same gauges, poses and noise: its 5 µm row is Table I's n = 5."""
    noise = noise_study(NoiseConfig(noise_um=(5.0,), gauges=3, poses=10, seed=3), scheduler=SERIAL)
    ours = {r["method"]: r for r in corners_small.table if r["n"] == 5 and r["m"] == 3}
    for r in noise.table:
        for key in TABLE1_COLUMNS[3:]:
            assert r[key] == ours[r["method"]][key]


def test_noise_study(tmp_path):
    levels = (0.0, 5.0, 15.0, 30.0)
    study = noise_study(NoiseConfig(noise_um=levels, gauges=3, poses=15, seed=5), scheduler=SERIAL)
    write_report(study, tmp_path)
    header, rows = _read_csv(tmp_path / "fig3.csv")
    assert header[:2] == ["noise_um", "method"]
    for method in ("cf", "mle"):
        mean = [float(r["reproj_mean_um"]) for r in rows if r["method"] == method]
        std = [float(r["reproj_std_um"]) for r in rows if r["method"] == method]
        assert mean[0] < 1e-3 and all(np.diff(mean) > 0) and all(np.diff(std) > 0)
    by = {(float(r["noise_um"]), r["method"]): r for r in rows}
    for level in levels[1:]:
        assert float(by[(level, "mle")]["reproj_mean_um"]) < 0.2 * float(by[(level, "cf")]["reproj_mean_um"])
    # CF-Opt's residual is linear in the noise: every level scales the same standard-normal draws
    # (common random numbers), and at the optimum the residual of a least-squares fit is the
    # noise projected off the model's tangent space, so reproj(σ) = σ·c + O(σ²/L) with L the
    # gauge's mm-size: per µm of noise the levels agree to well within 5 % (σ/L ≤ 30 µm / 20 mm).
    per_um = [float(by[(level, "mle")]["reproj_mean_um"]) / level for level in levels[1:]]
    np.testing.assert_allclose(per_um, per_um[0], rtol=0.05)
    _, cov = _read_csv(tmp_path / "noise_covariance.csv")
    assert len(cov) == 3 * len(levels)
    # Predicted vs empirical over N = 3 gauges × 15 poses = 45 errors per level and axis: with an
    # honest covariance N·rms² is χ²(45), whose 0.05 % and 99.95 % quantiles give rms in
    # [0.63, 1.42] (all 9 level-axis pairs together: ~1 % chance of a false alarm).
    lo, hi = np.sqrt(stats.chi2.ppf([5e-4, 1 - 5e-4], 45) / 45)
    for r in cov:
        if float(r["noise_um"]) > 0:
            assert lo < float(r["normalized_rms"]) < hi, r
            ratio = float(r["predicted_std_um"]) / float(r["empirical_rmse_um"])
            assert 1 / hi < ratio < 1 / lo, r
    _check_report(tmp_path)
    assert {"fig3_reprojection.png", "noise_predicted_vs_empirical.png"} <= {p.name for p in tmp_path.glob("*.png")}


@pytest.fixture(scope="module")
def limits_small():
    cfg = LimitsConfig(gauges=1, widths_mm=(80.0, 200.0), lengths_mm=(20.0, 40.0), betas_deg=(30.0, 50.0),
                       tilts_deg=tuple(range(-70, 71, 5)), tilt_poses=4, seed=2)
    return limits_study(cfg, scheduler=SERIAL)


def test_limits_tilt_cut_off_at_beta(limits_small):
    rows = tilt_summary(limits_small)
    for beta in (30.0, 50.0):
        rate = {r["alpha_deg"]: r["success_rate"] for r in rows if r["beta_deg"] == beta}
        assert rate[0.0] == 1.0
        assert all(v == 1.0 for a, v in rate.items() if abs(a) <= beta - 15)   # 15°: the fan's half-angle
        assert all(v == 0.0 for a, v in rate.items() if abs(a) >= beta + 3)   # self-occlusion past β
    actual = {r["beta_deg"]: r["beta_actual_deg"] for r in limits_small.tilts}
    for beta, b in actual.items():
        assert beta - 4 < b <= beta + 1e-9                            # ridge skew tilts faces a little more


def test_limits_range_of_motion(limits_small, tmp_path):
    summary = {(r["axis"], r["size_mm"]): r for r in range_summary(limits_small)}
    # x: the sum of the margins, shrinking about 1:1 with the gauge's width
    x80, x200 = summary[("x", 80.0)], summary[("x", 200.0)]
    slope = (x200["range_visible_mean_mm"] - x80["range_visible_mean_mm"]) / 120.0
    assert -1.2 < slope < -0.6
    assert x80["range_tracked_mean_mm"] > x200["range_tracked_mean_mm"] > 0
    for key in (("x", 80.0), ("x", 200.0)):
        assert summary[key]["range_tracked_mean_mm"] >= summary[key]["range_visible_mean_mm"] - 1.0
        assert abs(summary[key]["range_visible_mean_mm"] - summary[key]["margin_model_mm"]) < 20.0
    # z: most of the 315 mm depth range for a gauge narrower than the near width
    assert 250 < summary[("z", 80.0)]["range_tracked_mean_mm"] < 315
    # y: the gauge's length
    for length in (20.0, 40.0):
        assert length - 1.0 < summary[("y", length)]["range_tracked_mean_mm"] <= length + 0.5
        assert summary[("y", length)]["range_visible_mean_mm"] == pytest.approx(length - 6.0, abs=0.6)
    write_report(limits_small, tmp_path)
    header, rows = _read_csv(tmp_path / "limits_tilt.csv")
    assert header == ["beta_deg", "alpha_deg", "trials", "success_rate", "visible_rate"]
    assert len(rows) == 2 * 29
    _check_report(tmp_path)
    assert {"fig4a_range.png", "fig4b_tilt.png"} <= {p.name for p in tmp_path.glob("*.png")}


def test_study_configs_reject_bad_values():
    with pytest.raises(ConfigError, match=r"corners: expected integers >= 4, got \[3, 5\]"):
        CornersConfig(corners=(3, 5))
    with pytest.raises(ConfigError, match="poses: expected >= 1 pose per gauge, got 0"):
        CornersConfig(poses=0)
    with pytest.raises(ConfigError, match=r"noise_um: expected noise levels >= 0 µm, got \[-5.0\]"):
        NoiseConfig(noise_um=(-5,))
    with pytest.raises(ConfigError, match="mounting: expected one of auto, normal, reversed, got 'up'"):
        NoiseConfig(mounting="up")
    with pytest.raises(ConfigError, match="betas_deg: expected values in"):
        LimitsConfig(betas_deg=(95.0,))


# --------------------------------------------------------------------------- CLI


def _cli(argv):
    """``posekit profiler ARGV`` with only the study verb (cli/profiler.py wires the same parser)."""
    parser = argparse.ArgumentParser(prog="posekit profiler")
    verbs = parser.add_subparsers(dest="verb", required=True)
    add_study_parser(verbs)
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.mark.slow
def test_cli_study_corners_and_limits(tmp_path, capsys):
    out = tmp_path / "c"
    assert _cli(["study", "corners", "--corners", "4,5", "--gauges", "2", "--poses", "4", "--seed", "1",
                 "--scheduler", "serial", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"^cf\s+4\s+2\s+nan / nan .* 8$", printed, re.MULTILINE)
    assert f"wrote {out / 'report.html'}" in printed
    assert tuple(_read_csv(out / "table1.csv")[0]) == TABLE1_COLUMNS
    out = tmp_path / "l"
    assert _cli(["study", "limits", "--gauges", "1", "--widths-mm", "120", "--lengths-mm", "20",
                 "--betas-deg", "45", "--tilts-deg", "0:60:30", "--tilt-poses", "2", "--scheduler", "serial",
                 "--out", str(out)]) == 0
    _, rows = _read_csv(out / "limits_tilt.csv")
    assert [(float(r["alpha_deg"]), float(r["success_rate"])) for r in rows] == [(0, 1), (30, 1), (60, 0)]


def test_cli_study_bad_flags(tmp_path):
    with pytest.raises(ConfigError, match=r"^--gauges: expected comma-separated numbers or START:STOP:STEP, got 'a'$"):
        _cli(["study", "corners", "--gauges", "a", "--out", str(tmp_path)])
    with pytest.raises(ConfigError, match="--workers sets the size of the local cluster"):
        _cli(["study", "noise", "--workers", "2", "--scheduler", "serial", "--out", str(tmp_path)])
    with pytest.raises(PosekitError, match="scheduler: expected 'serial' or a Dask address"):
        _cli(["study", "noise", "--gauges", "1", "--poses", "1", "--scheduler", "localhost",
              "--out", str(tmp_path)])
    assert parse_numbers("0:10:5", "x") == (0.0, 5.0, 10.0)
    assert parse_numbers("4,5", "x", integer=True) == (4, 5)
    with pytest.raises(ConfigError, match="--corners: expected integers, got '4.5'"):
        parse_numbers("4.5", "corners", integer=True)
