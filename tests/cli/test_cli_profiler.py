"""Smoke and contract tests of ``posekit profiler simulate|estimate`` (DESIGN.md), in-process.

Every example gauge is simulated and estimated through ``posekit.cli.main.main(argv)``;
the records are checked field by field against the simulator's ``truth.csv``.
"""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from posekit import __version__
from posekit.cli.main import main
from posekit.profiler.gauge.model import load_gauge
from posekit.profiler.sim.simulate import read_truth_csv

GAUGE_DIR = Path(__file__).resolve().parents[2] / "examples" / "gauges"
GAUGES = sorted(GAUGE_DIR.glob("*.yaml"))
N_CORNERS = {g.stem: load_gauge(g).n_corners for g in GAUGES}
DEMO4 = GAUGE_DIR / "demo-4.yaml"
DEMO5 = GAUGE_DIR / "demo-5.yaml"

COUNT = 5
N_POINTS = 3200                      # LJ-X8400-like profiler: rays per profile
RECORD_KEYS = {"index", "status", "t_mm", "q_wxyz", "reprojection_um", "corners_mm", "std_t_um",
               "std_rot_deg", "chi2", "dof", "reason", "error"}
CSV_HEADER = ("index,status,tx,ty,tz,qw,qx,qy,qz,reprojection_um,error,std_tx_um,std_ty_um,std_tz_um,std_rx_deg,"
              "std_ry_deg,std_rz_deg,chi2,dof,reason")
TRUTH_HEADER = "index,tx,ty,tz,qw,qx,qy,qz"

#: Tolerances against truth at 1 µm noise (y is the weakly observable axis: its predicted
#: std is ~35-65 µm there, ~150-330 µm at the default 5 µm).
TOL_T_MM = 0.5
TOL_Q = 0.01
#: Zero noise: the estimate must reproduce the simulated pose.
TOL_T_EXACT_MM = 1e-6
TOL_Q_EXACT = 1e-8

# (gauge, method) pairs where the method applies: the closed form needs >= 5 corners.
GAUGE_METHODS = [pytest.param(g, m, id=f"{g.stem}-{m}") for g in GAUGES for m in ("mle", "cf")
                 if m == "mle" or N_CORNERS[g.stem] >= 5]
GAUGE_PARAMS = [pytest.param(g, id=g.stem) for g in GAUGES]


def run(capsys, *argv):
    """``posekit ARGV`` in-process; returns (exit code, stdout, stderr)."""
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def simulate(capsys, gauge, out, *, count=COUNT, seed=1, noise_um=None):
    argv = ["profiler", "simulate", "--gauge", gauge, "--count", count, "--seed", seed, "--out", out]
    if noise_um is not None:
        argv += ["--noise-um", noise_um]
    rc, stdout, err = run(capsys, *argv)
    assert rc == 0, err
    assert err == ""
    return out / "profiles.npz", out / "truth.csv"


#: The summary line of a batch too small to test the gauge file with (tests/profiler/test_gauge_check.py).
NOT_CHECKED = "posekit: note: the gauge file could not be checked by this batch: "


def estimate(capsys, inp, gauge, *extra):
    """Run estimate; returns (exit code, records from stdout, stderr). The batches here are smaller
    than the test of the gauge file needs, and such a batch gets no note about it."""
    rc, out, err = run(capsys, "profiler", "estimate", inp, "--gauge", gauge, *extra)
    assert NOT_CHECKED not in err, err
    return rc, [json.loads(line) for line in out.splitlines()], err


def load_profiles(path):
    with np.load(path) as data:
        return data["profiles"]


def assert_matches_truth(records, truth_csv, tol_t, tol_q):
    index, t_true, q_true = read_truth_csv(truth_csv)
    assert [r["index"] for r in records] == index.tolist()
    t = np.array([r["t_mm"] for r in records])
    q = np.array([r["q_wxyz"] for r in records])
    assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-9)
    q *= np.sign(np.sum(q * q_true, axis=1))[:, None]       # q and -q are the same rotation
    assert_allclose(t, t_true, rtol=0, atol=tol_t)
    assert_allclose(q, q_true, rtol=0, atol=tol_q)


def same_record(a, b):
    """Equal records, but for the quaternion's sign (canonical alone, continuous along a batch)."""
    qa, qb = np.array(a["q_wxyz"]), np.array(b["q_wxyz"])
    assert_array_equal(qa, qb * np.sign(qa @ qb))
    return {**a, "q_wxyz": None} == {**b, "q_wxyz": None}


def write_profile_csv(path, profile):
    """A profile as CSV ``x,z`` with empty cells for NaN (exact float round trip)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x", "z"])
        for x, z in profile:
            w.writerow(["" if np.isnan(v) else repr(float(v)) for v in (x, z)])


# --- top level ------------------------------------------------------------------------

def test_version(capsys):
    rc, out, err = run(capsys, "--version")
    assert rc == 0
    assert out.strip() == f"posekit {__version__}"


def test_no_command_is_usage_error(capsys):
    rc, out, err = run(capsys)
    assert rc == 2
    assert "usage:" in err


def test_profiler_without_verb_is_usage_error(capsys):
    rc, _, err = run(capsys, "profiler")
    assert rc == 2
    assert "usage:" in err


# --- simulate -------------------------------------------------------------------------

@pytest.mark.parametrize("gauge", GAUGE_PARAMS)
def test_simulate_writes_profiles_and_truth(capsys, tmp_path, gauge):
    npz, truth = simulate(capsys, gauge, tmp_path / "sim")
    profiles = load_profiles(npz)
    assert profiles.shape == (COUNT, N_POINTS, 2)
    assert profiles.dtype == np.float64
    assert not np.any(np.isinf(profiles))
    assert np.isfinite(profiles[..., 0]).sum(axis=1).min() > 100      # the gauge is in view
    lines = truth.read_text().splitlines()
    assert lines[0] == TRUTH_HEADER
    assert len(lines) == COUNT + 1
    index, t, q = read_truth_csv(truth)
    assert_array_equal(index, np.arange(COUNT))
    assert np.all(np.isfinite(t))
    assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("gauge", GAUGE_PARAMS)
def test_simulate_same_seed_same_profiles(capsys, tmp_path, gauge):
    npz_a, truth_a = simulate(capsys, gauge, tmp_path / "a", seed=7)
    npz_b, truth_b = simulate(capsys, gauge, tmp_path / "b", seed=7)
    npz_c, truth_c = simulate(capsys, gauge, tmp_path / "c", seed=8)
    a, b, c = load_profiles(npz_a), load_profiles(npz_b), load_profiles(npz_c)
    assert_array_equal(a, b)                      # NaN == NaN for assert_array_equal
    assert truth_a.read_text() == truth_b.read_text()
    assert not np.array_equal(a, c, equal_nan=True)
    assert truth_a.read_text() != truth_c.read_text()


# --- estimate: records against truth ----------------------------------------------------

@pytest.mark.parametrize("gauge, method", GAUGE_METHODS)
def test_estimate_matches_truth(capsys, tmp_path, gauge, method):
    npz, truth = simulate(capsys, gauge, tmp_path / "sim", noise_um=1)
    rc, records, err = estimate(capsys, npz, gauge, "--method", method)
    assert rc == 0, err
    assert err == ""
    assert len(records) == COUNT
    n = N_CORNERS[gauge.stem]
    for k, rec in enumerate(records):
        assert set(rec) == RECORD_KEYS
        assert rec["index"] == k
        assert rec["status"] == "ok"
        assert rec["error"] is None
        assert len(rec["t_mm"]) == 3
        assert len(rec["q_wxyz"]) == 4
        assert len(rec["std_t_um"]) == 3
        assert len(rec["std_rot_deg"]) == 3
        assert np.shape(rec["corners_mm"]) == (n, 2)
        assert np.isfinite(rec["reprojection_um"]) and rec["reprojection_um"] >= 0
        assert rec["dof"] == 2 * n - 6 and 0 <= rec["chi2"] < 5 * rec["dof"] + 10
        assert rec["reason"] is None
        # the closed form's standard deviations come from its own linearisation
        assert all(s > 0 for s in rec["std_t_um"] + rec["std_rot_deg"])
    assert_matches_truth(records, truth, TOL_T_MM, TOL_Q)


@pytest.mark.parametrize("gauge, method", GAUGE_METHODS)
def test_estimate_zero_noise_is_exact(capsys, tmp_path, gauge, method):
    npz, truth = simulate(capsys, gauge, tmp_path / "sim", noise_um=0)
    rc, records, err = estimate(capsys, npz, gauge, "--method", method)
    assert rc == 0, err
    assert [r["status"] for r in records] == ["ok"] * COUNT
    assert_matches_truth(records, truth, TOL_T_EXACT_MM, TOL_Q_EXACT)
    assert max(r["reprojection_um"] for r in records) < 1e-3


@pytest.mark.parametrize("gauge", GAUGE_PARAMS)
def test_estimate_default_noise_within_predicted_std(capsys, tmp_path, gauge):
    """At the default 5 µm the MLE error stays within 5 of its own predicted σ per axis."""
    npz, truth = simulate(capsys, gauge, tmp_path / "sim")
    rc, records, err = estimate(capsys, npz, gauge)
    assert rc == 0, err
    _, t_true, _ = read_truth_csv(truth)
    t = np.array([r["t_mm"] for r in records])
    std_mm = np.array([r["std_t_um"] for r in records]) * 1e-3
    assert np.all(np.abs(t - t_true) <= 5 * std_mm + 1e-3)
    assert np.all(np.abs(t - t_true)[:, [0, 2]] < TOL_T_MM)      # x and z are well observed


@pytest.mark.parametrize("gauge", [g for g in GAUGES if N_CORNERS[g.stem] >= 5], ids=lambda g: g.stem)
def test_mle_reprojection_not_worse_than_cf(capsys, tmp_path, gauge):
    """The MLE minimises the reprojection error the closed form only approximates."""
    npz, _ = simulate(capsys, gauge, tmp_path / "sim", noise_um=1)
    _, cf, _ = estimate(capsys, npz, gauge, "--method", "cf")
    _, mle, _ = estimate(capsys, npz, gauge, "--method", "mle")
    for a, b in zip(mle, cf):
        assert a["reprojection_um"] <= b["reprojection_um"] + 1e-6


# --- estimate: output files -----------------------------------------------------------

def test_estimate_out_csv_and_jsonl(capsys, tmp_path):
    npz, truth = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=1)
    rc, records, _ = estimate(capsys, npz, DEMO5)
    assert rc == 0
    out = tmp_path / "stdout.jsonl"

    rc, stdout, err = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5, "--out", out)
    assert rc == 0, err
    assert stdout == ""
    assert [json.loads(line) for line in out.read_text().splitlines()] == records

    out_csv = tmp_path / "poses.csv"
    rc, stdout, err = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5, "--out", out_csv)
    assert rc == 0, err
    assert stdout == ""
    text = out_csv.read_text()
    assert text.splitlines()[0] == CSV_HEADER
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == COUNT
    for rec, row in zip(records, rows):
        assert int(row["index"]) == rec["index"]
        assert row["status"] == "ok"
        assert row["error"] == ""
        assert [float(row[c]) for c in ("tx", "ty", "tz")] == rec["t_mm"]
        assert [float(row[c]) for c in ("qw", "qx", "qy", "qz")] == rec["q_wxyz"]
        assert float(row["reprojection_um"]) == rec["reprojection_um"]


def test_estimate_out_jsonl_equals_stdout(capsys, tmp_path):
    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim")
    rc, stdout, _ = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5)
    assert rc == 0
    out = tmp_path / "poses.jsonl"
    rc, stdout_file, _ = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5, "--out", out)
    assert rc == 0
    assert stdout_file == ""
    assert out.read_text() == stdout


# --- closed form needs 5 corners ------------------------------------------------------

def test_demo4_cf_fails_every_record_mle_succeeds(capsys, tmp_path):
    npz, truth = simulate(capsys, DEMO4, tmp_path / "sim", noise_um=1)
    rc, records, err = estimate(capsys, npz, DEMO4, "--method", "cf")
    assert rc == 1
    assert [r["index"] for r in records] == list(range(COUNT))
    for rec in records:
        assert set(rec) == RECORD_KEYS
        assert rec["status"] == "error"
        assert "5 corners" in rec["error"]
        assert rec["t_mm"] is None and rec["q_wxyz"] is None
    assert f"{COUNT} of {COUNT} profiles failed" in err
    assert "Traceback" not in err

    rc, records, err = estimate(capsys, npz, DEMO4, "--method", "mle")
    assert rc == 0, err
    assert [r["status"] for r in records] == ["ok"] * COUNT
    assert_matches_truth(records, truth, TOL_T_MM, TOL_Q)


# --- single-profile inputs ------------------------------------------------------------

def test_estimate_csv_input(capsys, tmp_path):
    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=1)
    profile = load_profiles(npz)[2]
    assert np.isnan(profile).any()                # NaN cells become empty cells
    path = tmp_path / "profile.csv"
    write_profile_csv(path, profile)
    assert "," in path.read_text().splitlines()          # a row with both cells empty

    rc, records, err = estimate(capsys, path, DEMO5)
    assert rc == 0, err
    assert len(records) == 1
    assert records[0]["index"] == 0 and records[0]["status"] == "ok"
    # The same numbers as the batch gives for that profile.
    _, batch, _ = estimate(capsys, npz, DEMO5)
    assert same_record(records[0], {**batch[2], "index": 0})


def test_estimate_npy_input(capsys, tmp_path):
    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=1)
    profile = load_profiles(npz)[3]
    path = tmp_path / "profile.npy"
    np.save(path, profile)
    rc, records, err = estimate(capsys, path, DEMO5)
    assert rc == 0, err
    assert len(records) == 1
    _, batch, _ = estimate(capsys, npz, DEMO5)
    assert same_record(records[0], {**batch[3], "index": 0})


def test_estimate_bundled_gauge_name(capsys, tmp_path):
    npz, _ = simulate(capsys, "demo-5", tmp_path / "sim", noise_um=1)
    _, by_name, _ = estimate(capsys, npz, "demo-5")
    rc, by_path, err = estimate(capsys, npz, DEMO5)
    assert rc == 0, err
    assert by_name == by_path


# --- a batch with bad profiles never drops an item -------------------------------------

def test_batch_with_failed_profiles_keeps_every_record(capsys, tmp_path):
    npz, truth = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=1)
    profiles = load_profiles(npz)
    profiles[1] = np.nan                                        # nothing in view
    profiles[3, : int(0.6 * N_POINTS)] = np.nan                 # the gauge's left part cut off
    path = tmp_path / "batch.npz"
    np.savez(path, profiles=profiles)

    rc, records, err = estimate(capsys, path, DEMO5)
    assert rc == 1
    assert [r["index"] for r in records] == list(range(COUNT))
    assert [r["status"] for r in records] == ["ok", "error", "ok", "error", "ok"]
    for rec in records:
        assert set(rec) == RECORD_KEYS
    assert "no valid points" in records[1]["error"]
    assert "missing corner" in records[3]["error"]
    assert "expected 5 corners for gauge 'demo-5'" in records[3]["error"]
    for k in (1, 3):
        assert records[k]["t_mm"] is None and records[k]["corners_mm"] is None
    for k in (0, 2, 4):
        assert records[k]["error"] is None
    ok = [records[k] for k in (0, 2, 4)]
    index, t_true, q_true = read_truth_csv(truth)
    assert_allclose([r["t_mm"] for r in ok], t_true[[0, 2, 4]], rtol=0, atol=TOL_T_MM)
    assert "2 of 5 profiles failed" in err
    assert "Traceback" not in err

    # CSV output of the same batch: error rows keep their place, with the reason.
    out_csv = tmp_path / "poses.csv"
    rc, _, _ = run(capsys, "profiler", "estimate", path, "--gauge", DEMO5, "--out", out_csv)
    assert rc == 1
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["index"]) for r in rows] == list(range(COUNT))
    assert [r["status"] for r in rows] == ["ok", "error", "ok", "error", "ok"]
    assert "no valid points" in rows[1]["error"]
    assert rows[1]["tx"] == "" and rows[1]["qw"] == "" and rows[1]["reprojection_um"] == ""


# --- the verdict: ok / suspect / error, and the exit code -------------------------------

SUSPECT_NOTE = ("posekit: 5 of 5 profiles are suspect (the data disagree with the gauge or the assumed noise); "
                "their records have status 'suspect' and the reason")


def test_noisier_than_assumed_is_suspect_and_exit_1(capsys, tmp_path):
    """15/30 µm noise against the assumed 5/10 µm: every record suspect, written whole; exit 1."""
    npz, truth = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=15)
    rc, records, err = estimate(capsys, npz, DEMO5)
    assert rc == 1
    assert err.strip() == SUSPECT_NOTE
    assert [r["status"] for r in records] == ["suspect"] * COUNT
    for rec in records:
        assert set(rec) == RECORD_KEYS
        assert rec["error"] is None and rec["t_mm"] is not None           # the numbers are kept
        assert "the profile scatters " in rec["reason"]
    # told the noise, the same profiles are ok
    rc, records, err = estimate(capsys, npz, DEMO5, "--noise-um", "15")
    assert rc == 0, err
    assert [r["status"] for r in records] == ["ok"] * COUNT
    assert_matches_truth(records, truth, 1.0, 0.01)


def test_wrong_gauge_file_is_suspect_in_csv(capsys, tmp_path):
    from posekit.profiler.gauge.design import random_gauge
    from posekit.profiler.gauge.model import gauge_to_yaml

    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim", noise_um=1)
    other = tmp_path / "other.yaml"
    other.write_text(gauge_to_yaml(random_gauge(5, 3)))
    out_csv = tmp_path / "poses.csv"
    rc, stdout, err = run(capsys, "profiler", "estimate", npz, "--gauge", other, "--out", out_csv)
    assert rc == 1
    with open(out_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == COUNT and "ok" not in {r["status"] for r in rows}  # never ok on a wrong gauge
    for row in (r for r in rows if r["status"] == "suspect"):
        assert float(row["chi2"]) > 1e3 and row["dof"] == "4"
        assert row["reason"].startswith("chi2 = ") and "do not fit gauge 'random-5'" in row["reason"]
        assert row["error"] == "" and row["tx"] != ""


def test_csv_carries_the_std_and_chi2_of_the_json(capsys, tmp_path):
    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim")
    for method in ("mle", "cf"):
        rc, records, err = estimate(capsys, npz, DEMO5, "--method", method)
        assert rc == 0, err
        out_csv = tmp_path / f"{method}.csv"
        rc, _, err = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5, "--method", method, "--out", out_csv)
        assert rc == 0, err
        with open(out_csv, newline="") as fh:
            rows = list(csv.DictReader(fh))
        for rec, row in zip(records, rows):
            assert [float(row[c]) for c in ("std_tx_um", "std_ty_um", "std_tz_um")] == rec["std_t_um"]
            assert [float(row[c]) for c in ("std_rx_deg", "std_ry_deg", "std_rz_deg")] == rec["std_rot_deg"]
            assert float(row["chi2"]) == rec["chi2"] and int(row["dof"]) == rec["dof"] == 4
            assert row["reason"] == ""


def test_gauge_tolerance_from_the_file(capsys, tmp_path):
    """A face 20 µm off its drawing: suspect with tolerance_um: 2, ok with tolerance_um: 30."""
    import yaml

    from posekit.profiler import NoiseModel, render_profiles, sample_poses

    nominal = load_gauge(DEMO5)
    doc = yaml.safe_load(DEMO5.read_text())
    doc["planes"][2]["offset"] += 0.020 * float(np.linalg.norm(doc["planes"][2]["normal"]))
    built = tmp_path / "built.yaml"
    built.write_text(yaml.safe_dump(doc))
    g_built = load_gauge(built)
    Ts = sample_poses(g_built, COUNT, rng=12)
    path = tmp_path / "p.npz"
    np.savez(path, profiles=render_profiles(g_built, Ts, NoiseModel(), rng=12))
    for tol, rc_expected, status in ((2, 1, "suspect"), (30, 0, "ok")):
        doc = yaml.safe_load(DEMO5.read_text())
        doc["tolerance_um"] = tol
        gauge = tmp_path / f"tol{tol}.yaml"
        gauge.write_text(yaml.safe_dump(doc))
        rc, records, err = estimate(capsys, path, gauge)
        assert rc == rc_expected, err
        assert [r["status"] for r in records] == [status] * COUNT
    assert nominal.tolerance_um == 0


def test_symmetric_gauge_needs_the_mounting(capsys, tmp_path):
    from posekit.profiler import NoiseModel, gauge_from_design, render_profiles, sample_poses
    from posekit.profiler.gauge.model import gauge_to_yaml

    a = [0.5, -0.45, 0.4, -0.4, 0.45, -0.5]
    u = [0.25, -0.1, 0.15, -0.1, 0.25]
    b2 = -u[2] * a[2]
    b0 = b2 - u[1] * (a[1] - a[2]) - u[0] * (a[0] - a[1])
    g = gauge_from_design("sym-5", [-45, -25, 0, 25, 45], a, u, y_slope0=b0, extent=((-60, 60), (-20, 20)),
                          mounting="normal")
    gauge = tmp_path / "sym.yaml"
    gauge.write_text(gauge_to_yaml(g))
    Ts = sample_poses(g, COUNT, rng=13)
    path = tmp_path / "p.npz"
    np.savez(path, profiles=render_profiles(g, Ts, NoiseModel(), rng=13))
    rc, records, err = estimate(capsys, path, gauge)
    assert rc == 1 and records == []
    from posekit.errors import one_line

    full = (f"{gauge}: gauge 'sym-5' is ambiguous: its cross-section is symmetric under a 180° turn about the "
            "vertical: read in reverse order, the corners fit the ridges exactly at another pose; give the mounting "
            "(--mounting normal|reversed)")
    assert err.strip() == "posekit: error: " + one_line(full, 300 - len("posekit: error: "))   # the line's 300
    rc, records, err = estimate(capsys, path, gauge, "--mounting", "normal")
    assert rc == 0, err
    assert [r["status"] for r in records] == ["ok"] * COUNT
    t = np.array([r["t_mm"] for r in records])
    assert np.all(np.abs(t - Ts[:, :3, 3])[:, [0, 2]] < TOL_T_MM)


@pytest.mark.parametrize("flags, message", [
    (["--significance", "0"], "--significance: expected a number > 0 and < 1, got 0"),
    (["--significance", "1"], "--significance: expected a number > 0 and < 1, got 1"),
    (["--noise-um", "0", "--noise-x-um", "0"],
     "--noise-um, --noise-x-um: the assumed noise must not be zero in both x and z"),
    (["--noise-um", "-1"], "--noise-um: expected a number in 0..10000 µm, got -1"),
])
def test_bad_verdict_flags(capsys, tmp_path, flags, message):
    npz, _ = simulate(capsys, DEMO5, tmp_path / "sim", count=1)
    rc, out, err = run(capsys, "profiler", "estimate", npz, "--gauge", DEMO5, *flags)
    assert rc == 1 and out == ""
    assert err.strip() == f"posekit: error: {message}"
