"""``posekit seam tune`` (src/posekit/seam/frontend/tune.py): the local-level fit against statsmodels, the latency
and noise it recovers on simulated episodes, its report and its one-line errors."""

import math
from pathlib import Path

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.seam.frontend.config import apply_overrides, config_from_dict
from posekit.seam.frontend.profile import load_profile
from posekit.seam.frontend.tune import local_level_fit, simulate_episodes, tune_profile, tune_report
from tests.cli_helpers import assert_one_line_error, run_cli


def test_local_level_fit_agrees_with_statsmodels():
    """A random walk of 0.02 per step seen through white noise of 0.05: our fit and statsmodels' local-level
    model (UnobservedComponents, exact likelihood) give the same variances; both near the truth."""
    sm = pytest.importorskip("statsmodels.api")
    rng = np.random.default_rng(3)
    n = 3000
    y = np.cumsum(0.02 * rng.standard_normal(n)) + 0.05 * rng.standard_normal(n)
    q, q_std, r, r_std = local_level_fit([y], [np.ones(n)])
    res = sm.tsa.UnobservedComponents(y, "local level").fit(disp=False)
    r2_sm, q2_sm = res.params  # sigma2.irregular, sigma2.level
    assert q == pytest.approx(math.sqrt(q2_sm), rel=0.03)
    assert r == pytest.approx(math.sqrt(r2_sm), rel=0.03)
    assert abs(q - 0.02) < 3 * q_std and abs(r - 0.05) < 3 * r_std
    assert 0 < q_std < 0.2 * q and 0 < r_std < 0.1 * r


STEPS = 160


@pytest.fixture(scope="module")
def episodes(tmp_path_factory):
    """Two short simulated episodes whose lasers read 15 ms late (declared nowhere), with truth.csv."""
    cfg = apply_overrides(config_from_dict({}), {"trajectory.steps": STEPS, "trajectory.length_mm": 100.0,
                                                  "filter.particles": 300, "simulation.laser_latency_s": [0.015]})
    return simulate_episodes(cfg, 2, 7, tmp_path_factory.mktemp("tune"))


def test_cli_tune_with_truth_recovers_the_latency_and_the_noise_and_feeds_track(episodes, tmp_path, capsys):
    """``posekit seam tune --with-truth --share-sensors`` on the two episodes (one test: under pytest-xdist a
    module fixture would run the ~10 s fit once per worker)."""
    out = tmp_path / "p.yaml"
    rc, stdout, err = run_cli(capsys, "seam", "tune", *map(str, episodes), "--with-truth", "--share-sensors",
                              "--out", out)
    assert rc == 0, err
    # a fit takes seconds to minutes: stderr says what it is doing, step by step, with the time since the start
    samples = sum(len((Path(e) / "log.csv").read_text().splitlines()) - 1 for e in episodes)
    *stages, offset, more = [ln.split("] ", 1)[1] for ln in err.splitlines() if ln.startswith("posekit seam tune: [")]
    walks = [getattr(load_profile(out).walk, a) for a in ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")]
    kept = sum(w.std is None for w in walks)            # not pinned: the coverage loop runs twice more with them
    passes = 3 + (6 if 0 < kept < 6 else 0) + 1
    assert stages == [f"{len(episodes)} episode(s), {samples} samples",
                      "fitting from the errors against truth.csv: lasers, plateau, walk, then the particle filter's "
                      "spread",
                      "the walk: the linearised filter's score at the truth, its best and the walks within one unit "
                      f"of it ({len(episodes)} episode(s) per evaluation)",
                      "the walk: scaled by the particle filter's coverage on the episodes "
                      f"({passes} passes of the filter over {len(episodes)} episode(s))",
                      "calibrating the integrity test: the lasers' innovations of the spread fit's particle filter"]
    # and the offset test's calibration: the smallest change it flags per axis (from two episodes: wide)
    assert offset.startswith("the offset test over 300 steps flags a change of the kinematics' offset of at least: "
                             "x ") and offset.endswith(" deg (more episodes make it smaller)"), offset
    assert more.startswith("with more episodes like these it would flag about (projected: the same spread, its "
                           "samples in proportion): 4 episodes: x ") and "; 6 episodes: x " in more, more
    p = load_profile(out)
    lat, sig = p.sensors[0].latency_s, p.sensors[0].sigma_mm
    assert not lat.note and abs(float(lat) - 0.015) < 0.003 and 0 < lat.std < 0.003
    # the residual at the true pose: the simulator's 0.05 mm of noise plus what the tool moves, off its program,
    # between the reading's time and the row's (measured 0.060 mm)
    assert not sig.note and 0.05 <= float(sig) <= 0.065 and 0 < sig.std < 0.002
    assert p.fitted.method == "truth" and sum(e.steps for e in p.fitted.episodes) == 2 * STEPS
    assert [e.name for e in p.fitted.episodes] == [d.name for d in episodes]
    assert f"wrote {out}" in stdout and "walk.x_mm" in stdout and "sensors[0].latency_s" in stdout
    assert " ms ± " in stdout
    assert stdout.splitlines()[-1] == (f"next: check it on episodes it was not fitted on: posekit seam track EPISODE "
                                       f"--profile {out} --out DIR (with a truth.csv, DIR/metrics.json has the 2σ "
                                       "coverage per axis and confident_wrong)")
    assert out.read_text().startswith("# posekit seam profile, fitted by: posekit seam tune ")
    # the profile feeds seam track
    rc, stdout, err = run_cli(capsys, "seam", "track", episodes[0], "--profile", out, "--out", tmp_path / "tr")
    assert rc in (0, 1), err
    assert "status:" in stdout


@pytest.mark.slow
def test_tune_from_innovations_alone_finds_the_latency(episodes):
    """No truth: the linearised filter's likelihood of the laser readings over the latency (and walk, noise)."""
    res = tune_profile(episodes, with_truth=False, share_sensors=True)
    lat = {v.key: v for v in res.values}["sensors[0].latency_s"]
    assert lat.pinned and abs(lat.value - 0.015) < 0.003, lat
    # its 95 % profile-likelihood interval (the walk and noise re-optimised at each latency, and the walk ten
    # times larger) covers the truth and is what the filter needs (measured 14.00-15.46 ms)
    lo, hi = lat.interval
    assert lo <= 0.015 <= hi and hi - lo <= 0.010 and lat.std == pytest.approx((hi - lo) / 3.92, rel=1e-3), lat
    assert res.method == "innovations" and res.episodes == 2 and res.steps == 2 * STEPS
    assert "sensors[0].latency_s" in tune_report(res)


def test_cli_tune_errors_are_one_line(episodes, tmp_path, capsys):
    import shutil

    (tmp_path / "exists.yaml").write_text("x")
    rc, out, err = run_cli(capsys, "seam", "tune", episodes[0], "--out", tmp_path / "exists.yaml")
    assert_one_line_error(rc, out, err, "exists.yaml: exists; expected a new file (or --overwrite)")
    rc, out, err = run_cli(capsys, "seam", "tune", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "seam tune: expected at least one LOGDIR (or --simulate RUNS)")
    bare = tmp_path / "bare"
    shutil.copytree(episodes[0], bare)
    (bare / "truth.csv").unlink()
    rc, out, err = run_cli(capsys, "seam", "tune", bare, "--with-truth", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "no truth.csv; expected one per episode with --with-truth")
    with pytest.raises(ConfigError):
        tune_profile([bare], with_truth=True)
    assert not (tmp_path / "p.yaml").exists()
    # --cross-check: refused before anything is fitted
    rc, out, err = run_cli(capsys, "seam", "tune", *episodes, "--cross-check", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--cross-check: needs --with-truth (each left-out episode is scored against "
                                        "its truth.csv)")
    rc, out, err = run_cli(capsys, "seam", "tune", episodes[0], "--with-truth", "--cross-check", "--out",
                           tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--cross-check: needs at least 2 episodes (each is left out in turn), got 1")
    rc, out, err = run_cli(capsys, "seam", "tune", "--simulate", "2", "--with-truth", "--cross-check", "--out",
                           tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--cross-check: recorded episodes only, not --simulate")
    # where its folds run: only with --cross-check, a local cluster's size or an address, not both
    rc, out, err = run_cli(capsys, "seam", "tune", *episodes, "--workers", "2", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--workers: only with --cross-check (its folds are what runs in parallel)")
    rc, out, err = run_cli(capsys, "seam", "tune", *episodes, "--with-truth", "--cross-check", "--scheduler",
                           "serial", "--workers", "2", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--workers sets the size of the local cluster; it cannot be combined with "
                                        "--scheduler")
    rc, out, err = run_cli(capsys, "seam", "tune", *episodes, "--with-truth", "--cross-check", "--scheduler",
                           "cluster:99999", "--out", tmp_path / "p.yaml")
    assert_one_line_error(rc, out, err, "--scheduler: expected 'serial' or a Dask address tcp://HOST:PORT with a "
                                        "port in 1..65535, got 'cluster:99999'")
    from posekit.seam.frontend.tune_check import cross_check

    with pytest.raises(ConfigError, match=r"bare has no truth.csv; expected every episode to have one"):
        cross_check([episodes[0], bare])
    assert not (tmp_path / "p.yaml").exists()


def test_plateau_factor_is_the_larger_rms_of_the_kinematics_and_the_filter_at_most_1():
    """The spread factor of an axis the robot plateau bounds (tune_truth._plateau_factor): errors drawn with a
    known rms over the spread give that rms back; the filter's own larger error wins; never above 1; its 1σ from
    the episodes' own rms."""
    from posekit.seam.frontend.tune_truth import _plateau_factor

    rng = np.random.default_rng(26)

    def draw(*scales, n=4000):
        return [s * rng.standard_normal(n) for s in scales]

    f, sd, kin = _plateau_factor(draw(0.6, 0.6, 0.6), draw(0.3, 0.4, 0.3))
    assert kin == pytest.approx(0.6, rel=0.03) and f == kin          # the kinematics' error: the filter learnt more
    assert 0.0 < sd < 0.02
    f, sd, kin = _plateau_factor(draw(0.5, 0.5), draw(0.7, 0.9))       # the filter worse than the kinematics
    assert kin == pytest.approx(0.5, rel=0.03) and f == pytest.approx(math.sqrt((0.49 + 0.81) / 2), rel=0.03)
    assert sd == pytest.approx(f * abs(math.log(0.9 / 0.7)) / math.sqrt(2) / math.sqrt(2), rel=0.1)
    f, sd, kin = _plateau_factor(draw(1.5), draw(0.3))                 # one episode: no 1σ; capped at 1
    assert f == 1.0 and sd is None and kin == pytest.approx(1.5, rel=0.03)


def test_cross_check_in_this_process_says_each_fold_as_it_starts_and_pools_by_steps(tmp_path, monkeypatch):
    """``--scheduler serial``: the folds one after the other, each announced; the table pools the left-out
    episodes' shares weighted by their steps (the folds' own fits are checked against a direct fit on the
    independent cell, tests/seam/test_seam_independent_cell.py)."""
    from posekit.seam.frontend import tune_check

    dirs = []
    for name in ("a", "b", "c"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "truth.csv").write_text("t")
        dirs.append(tmp_path / name)
    rows = {0: (100, [1.0] * 6, 1.0, 0.0), 1: (300, [0.8] * 6, 0.5, 0.1), 2: (100, [0.9] * 6, 0.0, 0.0)}
    seen = []
    monkeypatch.setattr(tune_check, "cross_check_fold", lambda task: (seen.append(task), rows[task[0]])[1])
    said = []
    check = tune_check.cross_check(dirs, base="base.yaml", share_sensors=True, stage=said.append, scheduler="serial")
    assert said == [f"cross-check {i}/3: fitting on the other 2 episode(s), tracking {n}"
                    for i, n in ((1, "a"), (2, "b"), (3, "c"))]
    assert seen == [(i, [str(d) for d in dirs], "base.yaml", True) for i in range(3)]
    p = check.pooled
    assert p["tracking"] == pytest.approx((100 * 1.0 + 300 * 0.5) / 500)
    assert p["confident_wrong"] == pytest.approx(300 * 0.1 / 500)
    assert p["coverage_2sigma"]["x"] == pytest.approx((100 * 1.0 + 300 * 0.8 + 100 * 0.9) / 500)
    assert p["episodes_confident_wrong_over_5_percent"] == 1
