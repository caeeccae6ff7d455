"""Tuning study (posekit.seam.frontend.study): OLS effects against a hand-rolled t-test, ranking, factors,
and a tiny end-to-end study that gives the same table in one process and on a 2-worker cluster."""

import csv

import numpy as np
import pytest
from scipy import stats

from posekit.errors import ConfigError, EstimationError
from posekit.seam.frontend.study_effects import ERROR_NAMES, RANKED_COLUMNS, fit_parameter_effects, rank_parameters
from posekit.seam.frontend.study_factors import Factor, get_dotted, make_factors, set_dotted

PARAMS = ("strong", "weak", "none_a", "none_b")


def _synthetic(seed=0, n=60):
    """x0 drives every error strongly, x1 only rz weakly, x2/x3 nothing."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([0, 0, 0, 0], [1, 2, 3, 4], size=(n, 4))
    Y = 0.1 * rng.standard_normal((n, 6))
    Y += 2.0 * X[:, [0]]
    Y[:, 5] += 0.05 * X[:, 1]
    return X, Y


def _ols_reference(X, y):
    """Textbook OLS: slopes and two-sided t-test p-values (numpy + scipy only)."""
    A = np.c_[np.ones(len(X)), X]
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ beta
    dof = len(X) - A.shape[1]
    s2 = resid @ resid / dof
    se = np.sqrt(np.diag(s2 * np.linalg.inv(A.T @ A)))
    t = beta / se
    return beta[1:], 2 * stats.t.sf(np.abs(t), dof)[1:]


def test_effects_match_textbook_ols():
    X, Y = _synthetic()
    eff = fit_parameter_effects(X, Y, PARAMS)
    assert eff.n == 60 and eff.coef.shape == (6, 4)
    for e in range(6):
        beta, p = _ols_reference(X, Y[:, e])
        np.testing.assert_allclose(eff.coef[e], beta, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(eff.pvalues[e], p, rtol=1e-6, atol=1e-300)
    np.testing.assert_allclose(eff.coef[:, 0], 2.0, atol=0.1)
    assert np.all(eff.log10_p[:, 0] < -30)
    assert np.all(eff.rsquared > 0.95)


def test_rank_puts_strong_factor_first():
    X, Y = _synthetic()
    factors = [Factor(n, 0.0, hi) for n, hi in zip(PARAMS, (1, 2, 3, 4))]
    rows = rank_parameters(fit_parameter_effects(X, Y, PARAMS), factors)
    assert [r["rank"] for r in rows] == [1, 2, 3, 4]
    assert rows[0]["parameter"] == "strong" and rows[0]["significant"] == "yes"
    assert rows[0]["range_effect_x_mm"] == pytest.approx(2.0, abs=0.1)       # slope 2 over a range of 1
    assert {r["parameter"] for r in rows[2:]} <= {"none_a", "none_b", "weak"}
    assert all(r["significant"] == "no" for r in rows if r["parameter"].startswith("none"))
    assert set(RANKED_COLUMNS) <= set(rows[0])
    mins = [r["min_log10_p"] for r in rows]
    assert mins == sorted(mins)


def test_effects_leave_out_failed_runs_and_refuse_too_few():
    X, Y = _synthetic(n=20)
    Y[3] = np.nan
    assert fit_parameter_effects(X, Y, PARAMS).n == 19
    with pytest.raises(EstimationError, match=r"parameter effects: 4 usable runs for 4 factors; need at least 6"):
        fit_parameter_effects(X[:5], Y[:5], PARAMS)
    X[:, 2] = 1.0
    with pytest.raises(EstimationError, match=r"factor\(s\) none_a do not vary"):
        fit_parameter_effects(X, Y, PARAMS)


def test_factors_and_dotted_keys():
    base = {"filter": {"sigma_t_mm": 0.02, "k_force_t": 0.0, "resampler": "systematic"}, "seed": 0}
    f = make_factors(base, ["filter.sigma_t_mm"], spread=0.5)
    assert f == (Factor("filter.sigma_t_mm", 0.01, 0.03),)
    assert make_factors(base, ["filter.sigma_t_mm"], ranges={"filter.k_force_t": (0.0, 1e-5)})[1] == \
        Factor("filter.k_force_t", 0.0, 1e-5)
    with pytest.raises(ConfigError, match=r"study factor 'filter.k_force_t': its base value is 0"):
        make_factors(base, ["filter.k_force_t"])
    with pytest.raises(ConfigError, match=r"study factor 'filter.nope': no such configuration key"):
        make_factors(base, ["filter.nope"])
    with pytest.raises(ConfigError, match=r"study factor 'filter.resampler': expected a numeric parameter"):
        make_factors(base, ["filter.resampler"])
    with pytest.raises(ConfigError, match=r"expected a range low < high, got \[2, 1\]"):
        Factor("a", 2.0, 1.0)
    d = {"a": {"b": 1}}
    set_dotted(d, "a.b", 5)
    assert get_dotted(d, "a.b") == 5
    assert ERROR_NAMES == ("rmse_x_mm", "rmse_y_mm", "rmse_z_mm", "rmse_rx_deg", "rmse_ry_deg", "rmse_rz_deg")


# --------------------------------------------------------------------------- end to end (tiny episodes)

TINY = {"seed": 2, "trajectory": {"kind": "xy", "length_mm": 30, "steps": 30}, "filter": {"particles": 40}}


def _read(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


def test_study_same_table_serial_and_cluster(tmp_path, capsys):
    """A tiny study: from the CLI in one process, and through a 2-worker Dask cluster (in-process
    workers, so the test does not pay for spawning interpreters) given as a Client and, from the
    CLI, as a tcp:// scheduler address, gives identical CSVs."""
    import yaml
    from distributed import Client, LocalCluster

    from posekit.cli.main import main
    from posekit.seam.frontend.config import config_from_dict
    from posekit.seam.frontend.study import seam_study, write_study
    from posekit.seam.frontend.study_factors import study_base
    from tests.seam.test_seam_plots import png_size

    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    serial = tmp_path / "serial"
    assert main(["seam", "study", "--config", str(cfg), "--runs", "6", "--seed", "11", "--scheduler", "serial",
                 "--parameters", "profile.walk.z_mm,profile.plateau.d0_mm=1:4", "--out", str(serial)]) == 0
    out = capsys.readouterr().out
    factors = make_factors(study_base(config_from_dict(TINY)), ["profile.walk.z_mm"],
                           ranges={"profile.plateau.d0_mm": (1.0, 4.0)})
    address = tmp_path / "address"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                      dashboard_address=":0") as cluster, Client(cluster, set_as_default=False) as client:
        study = seam_study(config_from_dict(TINY), runs=6, factors=factors, seed=11, scheduler=client)
        # and from the CLI, on the scheduler's address (what a user gives for a cluster)
        assert cluster.scheduler_address.startswith("tcp://")
        assert main(["seam", "study", "--config", str(cfg), "--runs", "6", "--seed", "11",
                     "--scheduler", cluster.scheduler_address,
                     "--parameters", "profile.walk.z_mm,profile.plateau.d0_mm=1:4", "--out", str(address)]) == 0
    dask = tmp_path / "dask"
    write_study(study, dask)
    for f in ("runs.csv", "parameters_ranked.csv"):
        assert _read(serial / f) == _read(dask / f), f
        assert _read(serial / f) == _read(address / f), f
    runs = _read(serial / "runs.csv")
    assert runs[0] == ["run", "status", *ERROR_NAMES, "error", "profile.walk.z_mm", "profile.plateau.d0_mm"]
    assert len(runs) == 7 and all(r[1] == "ok" for r in runs[1:])
    values = np.array([[float(v) for v in r[-2:]] for r in runs[1:]])
    s0 = config_from_dict(TINY).profile.walk.z_mm.value                      # the profile's walk z ± 50 %
    assert np.all((values[:, 0] >= 0.5 * s0 - 1e-12) & (values[:, 0] <= 1.5 * s0 + 1e-12))
    assert np.all((values[:, 1] >= 1.0) & (values[:, 1] <= 4.0))
    assert len(np.unique(values[:, 0])) == 6
    ranked = _read(serial / "parameters_ranked.csv")
    assert ranked[0] == list(RANKED_COLUMNS)
    assert sorted(r[1] for r in ranked[1:]) == ["profile.plateau.d0_mm", "profile.walk.z_mm"]
    assert png_size(serial / "fig6_pvalues.png") == (600, 580)
    assert (serial / "report.html").read_text().count("data:image/png;base64,") == 1
    assert "seam study: 6 runs × 1 episode(s), 2 parameters, 0 failed" in out


def test_a_failed_run_keeps_its_row(tmp_path, capsys, monkeypatch):
    """A run that breaks (here: a numerical error that is not a PosekitError, in run 1) is a row with
    status=error and the reason; the other runs, the models and the files go on; the CLI exits 1."""
    import yaml

    from posekit.cli.main import main
    from posekit.seam.frontend import episode

    real = episode.run_episode
    calls = []

    def flaky(cfg, seed=None, **kw):
        calls.append(seed)
        if len(calls) == 2:
            raise ZeroDivisionError("float division by zero")
        return real(cfg, seed, **kw)

    monkeypatch.setattr(episode, "run_episode", flaky)
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(yaml.safe_dump(TINY))
    rc = main(["seam", "study", "--config", str(cfg), "--runs", "5", "--scheduler", "serial",
               "--parameters", "profile.walk.z_mm", "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert rc == 1
    assert err == "posekit: error: 1 of 5 study runs failed; their rows in runs.csv say why\n"
    assert "seam study: 5 runs × 1 episode(s), 1 parameters, 1 failed" in out
    runs = _read(tmp_path / "out" / "runs.csv")
    head = runs[0]
    assert [r[head.index("status")] for r in runs[1:]] == ["ok", "error", "ok", "ok", "ok"]
    assert runs[2][head.index("error")] == "ZeroDivisionError: float division by zero"
    assert runs[2][head.index("rmse_x_mm")] == "nan" and runs[1][head.index("rmse_x_mm")] != "nan"
    ranked = _read(tmp_path / "out" / "parameters_ranked.csv")
    assert [r[1] for r in ranked[1:]] == ["profile.walk.z_mm"]      # the OLS used the 4 good runs


def test_integer_parameters_take_whole_values():
    """A factor on an integer key (the particle count) draws whole numbers, so its runs are valid."""
    from posekit.seam.frontend.config import config_from_dict
    from posekit.seam.frontend.study import seam_study

    study = seam_study(config_from_dict(TINY), runs=3, factors=[Factor("filter.particles", 20.0, 40.0)], seed=1,
                       scheduler="serial")
    assert study.status == ["ok", "ok", "ok"]
    values = study.X[:, 0]
    np.testing.assert_array_equal(values, np.round(values))
    assert np.all((values >= 20) & (values <= 40))
