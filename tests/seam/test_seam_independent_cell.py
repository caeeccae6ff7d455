"""The seam filter judged on a cell posekit's simulator did not make (tests/seam/independent_cell.py: its own
UR10-like arm, seam, deflection, drift and two lasers 13 / 17 ms late).

``seam tune --with-truth`` recovers the lasers' latencies from two short training episodes (2 x 120 steps, run here). The held-out
episodes are tracked with the profile the same command fitted on three full training episodes, checked in as
tests/seam/data/independent_cell_profile.yaml (a ~60 s fit; made by ``python -m tests.seam.independent_cell DIR``,
then in DIR ``posekit seam tune train0 train1 train2 --with-truth --out independent_cell_profile.yaml``; a test
here checks that the generator still writes the episodes the file names). Their 2-sigma coverage, tracking share
and confident-wrong share (tracking while beyond 3 sigma on some axis) are scored against the generator's own
truth, with bounds derived from the number of independent samples the autocorrelated steps are worth. The larger
Monte-Carlo (more episodes, encoder offsets, force biases) is benchmarks/seam_validation.py, written to
benchmarks/data/seam_validation.json.
"""

import csv
from pathlib import Path

import numpy as np
import pytest

from posekit.seam.frontend.logs import read_episode_log
from posekit.seam.frontend.profile import (
    default_profile,
    episode_record,
    load_profile,
    merge_profile,
    write_profile,
)
from posekit.seam.frontend.tracker import SeamTracker, step_record, track_log, write_track
from posekit.seam.frontend.tune import tune_profile, tune_report
from tests.cli_helpers import run_cli
from tests.seam import independent_cell as ic
from tests.seam.helpers import coverage_band, effective_samples

PROFILE = Path(__file__).parent / "data" / "independent_cell_profile.yaml"
HELD_OUT = (100, 101, 102, 103, 104, 105)


def _track(cell, root, seed, profile, name, **kw):
    ep = ic.episode(cell, seed, **kw)
    folder = ic.write_episode(root / f"{name}{seed}", cell, ep, declare_latency=False)
    r = track_log(read_episode_log(folder, profile=profile))
    return ic.scores(r.estimate, r.spread, r.status, ep)


def _needs(note: str) -> tuple[float, float]:
    """The least and largest share of the filter's own spread the episodes' errors needed, from the note of a
    spread factor kept at 1 (``... these episodes' errors need 0.32-0.81 of it ...``)."""
    lo, hi = note.split("errors need ")[1].split(" of it")[0].split("-")
    return float(lo), float(hi)


def test_tune_recovers_each_sensor_s_latency_within_3_ms(tmp_path):
    cell = ic.Cell()
    train = [ic.write_episode(tmp_path / f"train{s}", cell, ic.episode(cell, s, steps=120), declare_latency=False)
             for s in (0, 1)]
    res = tune_profile(train, with_truth=True)
    assert res.profile.bias_window == 10          # the episodes' filter.integrity_window
    got = {v.key: v for v in res.values}
    for i, true in enumerate(cell.latency_s):
        v = got[f"sensors[{i}].latency_s"]
        # measured (2 x 250 steps): 12.78 +- 0.48 ms and 16.91 +- 0.20 ms for the true 13 and 17 ms
        assert v.pinned and abs(v.value - true) < 0.003, (i, v)
        assert v.std is not None and 0.0 < v.std < 0.0015
        assert abs(v.value - true) < 4.0 * v.std + 0.001     # the 1σ is honest (1 ms: the servo lag, unmodelled)
    # the spread factors: fitted (at least 1, with a 1σ) or, where every episode's errors need less than the filter's
    # own spread, 1 without a 1σ and the share they needed said, or along the roll the robot plateau bounds (its walk
    # not pinned), from the kinematics' own error there (measured on 2 x 120 steps: y 1.32 and rz 1.04 fitted, x z rx
    # at 1 needing 0.46-0.94 of it, ry 0.69)
    for a in ("x", "y", "z", "rx", "ry", "rz"):
        v = got[f"spread.{a}"]
        if a == "ry":
            assert not got["walk.ry_deg"].pinned and v.note.startswith("the robot plateau bounds this axis"), v
            assert float(v.note.split("kinematics err by ")[1].split()[0]) <= v.value < 1.0 and v.std > 0.0, v
            continue
        assert v.pinned and v.value >= 1.0, v
        if v.std is None:
            lo, hi = _needs(v.note)
            assert v.value == 1.0 and 0.0 < lo <= hi < 1.0 and "a factor below 1 is not fitted" in v.note, v
        else:
            assert v.value > 1.0 and v.std > 0.0 and not v.note, v
    # and the laser noise to within a half of the generator's (0.03 / 0.04 mm plus the jitter the sensors see)
    for i, noise in enumerate(cell.laser_sigma_mm):
        assert noise < got[f"sensors[{i}].sigma_mm"].value < 1.5 * noise
    # the integrity test's calibration, from the filter run with all of it: every component pinned with a 1σ, its
    # mean within a factor 2 of the model's own 1 (measured on 3 x 400 steps: 0.79-0.93) and its degrees of freedom
    # per reading at most ~1 (correlated steps are worth less; measured 0.82-0.96)
    for i in range(len(cell.mounts)):
        for a in "xz":
            c, rho = got[f"sensors[{i}].nis_mean_{a}"], got[f"sensors[{i}].nis_dof_{a}"]
            assert c.pinned and rho.pinned and 0.5 < c.value < 2.0 and 0.0 < c.std < 0.2 * c.value, (c, rho)
            assert 0.2 < rho.value < 1.3 and rho.std is not None and 0.0 < rho.std < 0.5 * rho.value, rho
            # the bias test's: the squared mean of 10 signed innovations, near nis_mean / 10 when they are white
            # (measured 0.047-0.067), worth about 3 / (2 x 10) chi2 degrees of freedom per step (measured 0.08-0.19)
            b, brho = got[f"sensors[{i}].bias_mean_{a}"], got[f"sensors[{i}].bias_dof_{a}"]
            assert b.pinned and brho.pinned and b.std is not None and brho.std is not None, (b, brho)
            assert 0.3 * c.value / 10 < b.value < 3.0 * c.value / 10 and 0.03 < brho.value < 0.5, (b, brho)


@pytest.mark.slow
def test_tune_without_truth_is_never_confidently_wrong_about_a_latency(tmp_path, monkeypatch):
    """``seam tune`` from the laser innovations alone: here the robot's own unmodelled error wanders sideways with
    the seam's wave, as a latency does, and the likelihood (which trusts the random-walk model) alone puts sensor
    1's 13 ms at 0-3 ms. Each latency must come with a 95 % interval that covers the truth, or be marked not pinned
    (its base value kept and its reading noise widened for the latency it may have)."""
    from posekit.seam.frontend import tune_intervals

    monkeypatch.setattr(tune_intervals, "LATENCY_GRID_S", np.arange(0.0, 0.0501, 0.01))   # a coarser grid: ~2x faster
    cell = ic.Cell()
    train = [ic.write_episode(tmp_path / f"train{s}", cell, ic.episode(cell, s, steps=100), declare_latency=False)
             for s in (0, 1)]
    res = tune_profile(train)
    got = {v.key: v for v in res.values}
    base = read_episode_log(train[0]).config.profile.to_model().sensor_latency_s(len(cell.latency_s))  # kept
    for i, true in enumerate(cell.latency_s):
        v = got[f"sensors[{i}].latency_s"]
        lo, hi = v.interval
        assert 0.0 <= lo < hi <= 0.05, v
        if v.pinned:
            assert lo <= true <= hi and hi - lo <= 0.010, v
        else:
            assert v.value == pytest.approx(base[i]) and v.std is None and "95 % interval" in v.note and "declare it in setup.yaml" in v.note, v
            assert any(w in v.note for w in ("touches 0", "wider than", "confounded")), v
            sig = got[f"sensors[{i}].sigma_mm"]
            assert "widened by" in sig.note and sig.value > cell.laser_sigma_mm[i], sig
        # measured (2 x 100 steps): neither pinned, 95 % intervals 0-50 / 0-37 ms (3 x 400 steps and the 5 ms grid:
        # 0-21.2 ms not pinned, 15.6 ms pinned at 10.1-17.2 ms: benchmarks/seam_tune_innovations.py)
        assert lo <= true <= hi, v
    assert "[not pinned: 95 % interval" in tune_report(res)
    # what a latency anywhere in its interval would do to the pose is in the reported spread (frontend/tune_latency.py):
    # the factors are at least 1, the lateral ones above 1, and say why
    spread = {a: got[f"spread.{a}"] for a in ("x", "y", "z", "rx", "ry", "rz")}
    assert all(v.value >= 1.0 and "unpinned latency" in v.note for v in spread.values()), spread
    assert spread["y"].value > 1.2 and spread["rz"].value > 1.2, spread
    # (measured: x 4.1, y 2.9, rz 1.7, the others ~1.05) so a held-out episode tracked with this profile is not
    # confidently wrong (measured: 0 % on seeds 100-103, tracking 0.82-1.0; with the factors
    # at 1, 31 % over ten held-out episodes: docs/notes/issue-26.md)
    write_profile(tmp_path / "innovations.yaml", res.profile)
    held = _track(cell, tmp_path, HELD_OUT[0], tmp_path / "innovations.yaml", "held")
    assert held["confident_wrong"] <= 0.05 and held["tracking"] >= 0.9, held


def test_the_checked_in_profile_was_fitted_on_this_generator_s_episodes(tmp_path):
    p = load_profile(PROFILE)
    assert p.fitted.method == "truth"
    assert [episode_record(d) for d in ic.write_training(tmp_path)] == [e.model_dump() for e in p.fitted.episodes]
    # its spread factors as seam tune writes them: fitted above 1 with a 1σ (z, rx here), kept at 1 with the share
    # of the filter's own spread the training episodes' errors needed (x, y, rz: 0.30-0.77), or, on the axis the
    # robot plateau bounds (ry, the roll about the travel, which the lasers barely see), below 1 from the
    # kinematics' own error there (0.65 of the filter's spread) and the filter's (0.70)
    kept, plateau = {}, {}
    for a in ("x", "y", "z", "rx", "ry", "rz"):
        f = getattr(p.spread, a)
        if f.note is None:
            assert f.value > 1.0 and f.std is not None and 0.0 < f.std < f.value, (a, f)
        elif f.note.startswith("the robot plateau bounds this axis"):
            kin = float(f.note.split("kinematics err by ")[1].split()[0])
            assert kin <= f.value < 1.0 and 0.0 < f.std < 0.2 * f.value, (a, f)
            plateau[a] = kin
        else:
            assert f.value == 1.0 and f.std is None and f.note.endswith("of it (a factor below 1 is not fitted)"), f
            kept[a] = _needs(f.note)
    assert sorted(kept) == ["rz", "x", "y"] and sorted(plateau) == ["ry"], (kept, plateau)
    assert all(0.0 < lo <= hi < 1.0 for lo, hi in kept.values()), kept
    assert 0.5 < plateau["ry"] < 0.8, plateau


def test_held_out_episodes_are_tracked_with_an_honest_spread(tmp_path):
    cell = ic.Cell()
    runs = [_track(cell, tmp_path, s, PROFILE, "held") for s in HELD_OUT]
    covered = np.concatenate([r["covered"] for r in runs])
    cov = covered.mean(axis=0)
    n_eff = effective_samples(covered)          # 2400 steps, errors correlated over tens of steps: 10-900 per axis
    lo, _ = coverage_band(n_eff, 0.85)           # the issue's lower target, 3 binomial sigmas at n_eff
    assert np.all(cov >= lo), (cov, n_eff)
    # not too wide in translation: below the band of 0.99 (a rotation's n_eff is too small for the band to bind)
    _, hi = coverage_band(n_eff, 0.99)
    assert np.all(cov[:3] <= np.minimum(hi[:3], 0.999)), (cov, n_eff)
    # nor on the roll about the travel, which the lasers barely see: its spread is the robot plateau's, a bound on
    # the largest error, and its factor (0.70) comes from the kinematics' own error there (with the filter's own
    # spread it covered every step: 1.0)
    assert cov[4] <= 0.99, cov
    # over the held-out steps (measured: coverage 0.994 0.960 0.966 0.948 0.963 0.888, tracking 0.988,
    # confident-wrong 0.003, the worst episode 1.8 %)
    assert np.mean([r["tracking"] for r in runs]) >= 0.9
    assert np.mean([r["confident_wrong"] for r in runs]) <= 0.05


@pytest.mark.slow
def test_a_walk_the_data_do_not_decide_can_still_decide_an_episode_s_honesty(tmp_path):
    """Along the roll (ry) the robot plateau bounds the pose: the linearised filter's score is flat only about a walk
    near zero (within one unit of its best up to 0.00076 deg/√mm) and does not pin it. ``seam tune`` keeps the base
    profile's and says where the score stands there (95 units above its best: the note used to say the score did
    not depend on it). The particle filter's honesty does depend on it: the checked-in profile's 0.0068 deg/√mm (the
    shipped default's) and 0.62 times it (0.0042, what the default fitted when its yz episodes drew their own
    robots) leave held-out episode 120 1.5 % and 33 % confidently wrong (measured)."""
    prof = load_profile(PROFILE)
    note = prof.walk.ry_deg.note
    head, tail = note.split(" above it here; ")
    assert head.startswith("the base profile's: the linearised filter's score is within one unit of its best from 0 "
                           "to "), note
    bound, excess = (float(v) for v in head.rsplit(" to ", 1)[1].split(" and "))
    assert 0.0005 < bound < 0.001 and excess > 50.0, note   # 0.00076 and 95: the kept walk is far outside
    assert tail.startswith("kept, as along an axis the robot plateau bounds the particle filter with the score's walk "
                           "covered held-out episodes too little (measured)"), note
    assert prof.walk.ry_deg.std is None   # not a fitted value: no 1σ
    assert float(prof.walk.ry_deg) == pytest.approx(0.006805)
    narrower = write_profile(tmp_path / "narrower.yaml", merge_profile(prof, {"walk": {"ry_deg": 0.0042}}))
    cell = ic.Cell()
    ep = ic.episode(cell, 120)
    folder = ic.write_episode(tmp_path / "ep120", cell, ep, declare_latency=False)
    kept, narrow = (ic.scores(*_run(folder, p), ep) for p in (PROFILE, narrower))
    assert kept["confident_wrong"] < 0.05 and narrow["confident_wrong"] > 0.2, (kept, narrow)


@pytest.mark.slow
def test_a_fitted_walk_s_1sigma_takes_in_the_walks_the_data_do_not_decide(tmp_path):
    """The particle filter's coverage scales each pinned walk, and it runs with the undecided roll walk at the base
    profile's value: a pinned walk depends on that choice. From a base whose roll walk is 0.0042 deg/√mm instead of
    the default's 0.0068 the same three episodes give walk.y 0.0194 instead of 0.0346 mm/√mm, where the checked-in
    profile said ± 0.002 (7.6σ; measured). Its 1σ now takes in the range each pinned walk spans with the roll walk e
    times narrower to wider: the other base's values lie within 2σ of the checked-in ones on every pinned axis.
    From that base ``tune`` used to stop its optimiser part-way down the roll walk's slope and call 0.00063 pinned;
    it keeps the base's 0.0042 now, as from the default."""
    prof = load_profile(PROFILE)
    pinned = ("x_mm", "y_mm", "z_mm", "rx_deg", "rz_deg")
    for a in pinned:
        w = getattr(prof.walk, a)
        assert w.note.startswith("1σ ") and "from the walks they do not decide (walk.ry_deg e times narrower to " \
            "wider: " in w.note, (a, w.note)
        lo, hi = (float(v) for v in w.note.rsplit(": ", 1)[1].rstrip(")").split("-"))
        assert lo <= float(w) <= hi and w.std > 0.0, (a, w)
    other = merge_profile(default_profile(), {"walk": {"ry_deg": 0.0042}})
    refit = tune_profile(ic.write_training(tmp_path), with_truth=True, base=other).profile
    assert float(refit.walk.ry_deg) == pytest.approx(0.0042) and refit.walk.ry_deg.std is None
    for a in pinned:
        w, v = getattr(prof.walk, a), float(getattr(refit.walk, a))
        assert abs(v - float(w)) <= 2.0 * w.std, (a, v, float(w), w.std)
    assert float(refit.walk.y_mm) < 0.7 * float(prof.walk.y_mm)   # the dependence is real: 0.0194 against 0.0346


def _zero_latency_profile(tmp_path, cell):
    zero = merge_profile(load_profile(PROFILE), {"sensors": [{"latency_s": 0.0}] * len(cell.mounts)})
    return write_profile(tmp_path / "zero-latency.yaml", zero)


def test_a_latency_nobody_declared_is_degraded_not_tracking_wrong(tmp_path):
    """The profile (``seam tune --with-truth``) knows what its lasers' innovations look like on its training
    episodes; the same profile claiming no latency leaves sensor 2's lateral innovations with a bias that follows
    the seam's wave. Squared step by step it is 1.6x the profile's mean (the NIS test flagged it only after 132-259
    steps, 34 % of the steps confidently wrong over ten episodes); averaged over the profile's bias_window (10)
    steps first, 10-17x (the bias test). Measured (seeds 100-102): undeclared tracking 0.16 / 0.08 / 0.13,
    confident-wrong 0 / 0 / 0, first flag at steps 63 / 30 / 0 (a force flag there); declared 1.0 / 1.0 / 0.94
    tracking (before the bias test: undeclared 0.61 / 0.33 / 0.47)."""
    cell = ic.Cell()
    zero = _zero_latency_profile(tmp_path, cell)
    for seed in HELD_OUT[:3]:
        ep = ic.episode(cell, seed)
        folder = ic.write_episode(tmp_path / f"ep{seed}", cell, ep, declare_latency=False)
        declared = ic.scores(*_run(folder, PROFILE), ep)
        reasons = []
        undeclared = ic.scores(*_run(folder, zero, reasons), ep)
        assert declared["tracking"] >= 0.9 and declared["confident_wrong"] <= 0.05, (seed, declared)
        assert undeclared["tracking"] <= 0.2 and undeclared["confident_wrong"] <= 0.05, (seed, undeclared)
        # the steps it takes out of tracking are the bias test's, on the lateral reading of the sensor farthest
        # ahead (the one whose reading moves fastest)
        flagged = [r for r in reasons if r]
        assert sum(r.startswith("sensor 2's x innovations biased: their 10-step means over the last ")
                   for r in flagged) >= 0.9 * len(flagged)
    # the user reads the reason beside each step: estimates.csv's last column (empty while tracking) and the JSONL
    result = track_log(read_episode_log(folder, profile=zero))
    write_track(tmp_path, result)
    with (tmp_path / "estimates.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[-1] == "reason" and [r["status"] for r in rows] == result.status
    assert all((r["reason"] == "") == (r["status"] == "tracking") for r in rows)
    assert any(r["reason"].startswith("sensor 2's x innovations biased: ") for r in rows)
    tracker = SeamTracker(result.config, read_episode_log(folder).seam_mm)
    est = tracker.step(0.0, *_first_sample(folder))
    rec = step_record(0, est)             # (this sample's force is just beyond the fitted range: degraded, said why)
    assert rec["reason"] == est.raw.reason and (rec["reason"] is None) == (rec["status"] == "tracking"), rec


def _first_sample(folder):
    log = read_episode_log(folder)
    return log.qref[0], log.q[0], log.force_tool_n[0]


def _run(folder, profile, reasons=None):
    r = track_log(read_episode_log(folder, profile=profile),
                  on_step=None if reasons is None else (lambda k, e: reasons.append(e.raw.reason or "")))
    return r.estimate, r.spread, r.status


@pytest.mark.slow
def test_cross_check_scores_each_left_out_episode_as_the_generator_does(tmp_path, capsys):
    """``seam tune --with-truth --cross-check``: each episode tracked with a profile fitted on the others, the folds
    on a local Dask cluster of two processes; the row of a left-out episode is what the generator's own errors
    (``independent_cell.scores``) say of the same fold fitted and tracked in this process, and the pooled row is
    the step-weighted mean."""
    cell = ic.Cell()
    eps = {s: ic.episode(cell, s, steps=100) for s in (0, 1)}
    dirs = [ic.write_episode(tmp_path / f"e{s}", cell, ep, declare_latency=False) for s, ep in eps.items()]
    rc, out, err = run_cli(capsys, "seam", "tune", *dirs, "--with-truth", "--cross-check", "--workers", "2",
                           "--out", tmp_path / "p.yaml")
    assert rc == 0, err
    assert load_profile(tmp_path / "p.yaml").fitted.method == "truth"          # the profile itself, as without it
    assert ("cross-check: 2 folds in parallel, each fitting on the other 1 episode(s) and tracking the one left "
            "out") in err
    rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.startswith(("  e0 ", "  e1 ", "  pooled "))}
    assert sorted(rows) == ["e0", "e1", "pooled"], out
    assert "of 2 episode(s) more than 5 % confident-wrong" in out

    def numbers(r):   # coverage x..rz, tracking %, confident-wrong %
        return np.array([float(v) for v in r[1:7]] + [float(r[7]), float(r[9])])

    fitted = tune_profile([dirs[1]], with_truth=True).profile
    r = track_log(read_episode_log(dirs[0], profile=fitted))
    sc = ic.scores(r.estimate, r.spread, r.status, eps[0])
    want = np.r_[sc["coverage"], 100 * sc["tracking"], 100 * sc["confident_wrong"]]
    tol = np.r_[np.full(6, 5e-4), 0.05, 0.005]                  # as printed: 3 decimals, 0.1 % and 0.01 %
    assert np.all(np.abs(numbers(rows["e0"]) - want) <= tol), (rows["e0"], want)
    mean = (numbers(rows["e0"]) + numbers(rows["e1"])) / 2        # equal steps: the step-weighted mean
    assert np.all(np.abs(numbers(rows["pooled"]) - mean) <= 2 * tol), (rows["pooled"], mean)


PROFILE_9 = Path(__file__).parent / "data" / "independent_cell_profile_9.yaml"


@pytest.mark.slow
def test_an_encoder_offset_after_the_profile_was_fitted_is_flagged_by_the_offset_test(tmp_path):
    """A 0.05° offset of joint 2 that appeared after the profile was fitted moves the estimate's offset from the
    kinematic pose along z by 0.5 mm (the lasers see it) and leaves the roll 0.05° off (they do not): seed 117 was
    57 % confidently wrong. The offset test, calibrated by seam tune on the profile's 9 training episodes, flags
    it; on the same seed without the fault it flags nothing. Measured: faulty tracking 0.025 (from step 10,
    the first the long window tests, every step degraded by the offset along z: -0.18 mm against the profile's
    -0.66 ± 0.06), confident-wrong 0; nominal tracking 1.0, confident-wrong 0.035, no offset flag. (With the
    3-episode profile the test cannot pin the offset along z, the smallest change it flags there is 3.1 mm, and
    the faulty episode stays 57 % confidently wrong.)"""
    p = load_profile(PROFILE_9)
    assert p.offset is not None and len(p.fitted.episodes) == 9
    cell = ic.Cell()
    seed = 117
    for kw, faulty in (({"encoder_offset_deg": (0.0, 0.05, 0.0, 0.0, 0.0, 0.0)}, True), ({}, False)):
        ep = ic.episode(cell, seed, **kw)
        folder = ic.write_episode(tmp_path / f"ep{faulty}", cell, ep, declare_latency=False)
        reasons = []
        sc = ic.scores(*_run(folder, PROFILE_9, reasons), ep)
        by_offset = [r.startswith("the estimate's offset from the kinematic pose along ") for r in reasons]
        if faulty:
            assert sc["confident_wrong"] <= 0.05 and sum(by_offset) >= 0.8 * len(reasons), sc
            assert any(r.startswith("the estimate's offset from the kinematic pose along z ") for r in reasons)
        else:
            assert not any(by_offset) and sc["tracking"] >= 0.9 and sc["confident_wrong"] <= 0.05, sc


@pytest.mark.slow
def test_a_profile_from_nine_episodes_meets_the_issue_s_figures_and_flags_or_bounds_every_fault(tmp_path):
    """Issue 26's done-when and deliverable 4 with the profile ``seam tune --with-truth`` fitted on nine training
    episodes of this cell (four seconds each; tests/seam/data/independent_cell_profile_9.yaml, the command in its
    header), on the held-out episodes of the tests: nominal, a 2σ coverage no lower than the issue's 0.85 allows at
    the steps' independent samples, tracking ≥ 90 % and confident-wrong ≤ 5 %; under an encoder offset of 0.05° on
    joint 1 or 2 or a 300 N force-sensor bias along x or z, every single episode under 5 % confidently wrong or
    flagged (not ``tracking`` on most of its steps). Measured: nominal coverage 0.990 0.983 0.983 0.979 1.0 1.0,
    tracking 0.999, confident-wrong 0.0004; joint 2 flagged on every episode (tracking 0.025), the others tracking
    0.985-1.0 with the worst episode 4.3 % (force along x, seed 101). Over 30 held-out episodes
    (benchmarks/seam_validation.py) the joint-1 offset leaves 3 of them over 5 % (worst 8.8 %), as many as a
    perfectly honest spread leaves by chance (2.3)."""
    p = load_profile(PROFILE_9)
    assert len(p.fitted.episodes) == 9 and p.fitted.method == "truth"
    cell = ic.Cell()
    nominal = [_track(cell, tmp_path, s, PROFILE_9, "held") for s in HELD_OUT]
    covered = np.concatenate([r["covered"] for r in nominal])
    lo, _ = coverage_band(effective_samples(covered), 0.85)
    assert np.all(covered.mean(axis=0) >= lo), covered.mean(axis=0)
    assert np.mean([r["tracking"] for r in nominal]) >= 0.9
    assert np.mean([r["confident_wrong"] for r in nominal]) <= 0.05
    faults = {"joint 1": {"encoder_offset_deg": (0.05, 0, 0, 0, 0, 0)},
              "joint 2": {"encoder_offset_deg": (0, 0.05, 0, 0, 0, 0)},
              "force x": {"force_bias_n": (300.0, 0, 0)}, "force z": {"force_bias_n": (0, 0, 300.0)}}
    for name, kw in faults.items():
        runs = [_track(cell, tmp_path, s, PROFILE_9, name.replace(" ", ""), **kw) for s in HELD_OUT]
        for seed, r in zip(HELD_OUT, runs):
            assert r["confident_wrong"] <= 0.05 or r["tracking"] < 0.5, (name, seed, r["tracking"], r["confident_wrong"])
        if name == "joint 2":   # the offset the lasers see (0.5 mm along z) is flagged, not merely bounded
            assert max(r["tracking"] for r in runs) < 0.1, [r["tracking"] for r in runs]
