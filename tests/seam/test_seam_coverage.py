"""metrics.json's honesty fields (status_counts, coverage_2sigma, tracking_beyond_3sigma) against a
hand count, the per-step status columns, and the verdicts of short simulated episodes: nominal
mostly tracking, a robot 10x more compliant than the filter's model never confidently wrong."""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from posekit.seam.frontend.config import apply_overrides, config_from_dict, load_config
from posekit.seam.frontend.simulate import (
    STATUS_COLUMNS,
    confident_wrong_fraction,
    integrity_summary,
    metrics,
    run_episode,
    status_columns,
)


def _fake(errors, spreads, status):
    n = len(status)
    return SimpleNamespace(error=np.asarray(errors, float), spread=np.asarray(spreads, float),
                           status=np.asarray(status), t_s=np.arange(n) * 0.01)


def test_summary_counts_by_hand():
    s = np.ones((4, 6))
    e = np.zeros((4, 6))
    e[0, 0] = 1.9      # within 2 sigma
    e[1, 0] = -2.1     # outside 2 sigma, within 3
    e[2, 4] = 3.5      # beyond 3 sigma, reported tracking
    e[3, 5] = -4.0     # beyond 3 sigma, reported lost
    r = _fake(e, s, ["tracking", "degraded", "tracking", "lost"])
    cov, counts, beyond = integrity_summary([r, r])
    np.testing.assert_allclose(cov, [0.75, 1, 1, 1, 0.75, 0.75])
    assert counts == {"tracking": 4, "degraded": 2, "lost": 2}
    assert beyond == 0.5
    cols = status_columns(r)
    assert tuple(cols) == STATUS_COLUMNS == ("status", "std_x_mm", "std_y_mm", "std_z_mm", "std_rx_deg",
                                             "std_ry_deg", "std_rz_deg")
    assert cols["status"].tolist() == ["tracking", "degraded", "tracking", "lost"]
    assert integrity_summary([_fake(e[:2], s[:2], ["tracking"] * 2)])[2] is None  # no step beyond 3 sigma
    assert confident_wrong_fraction([r, r]) == 0.25  # step 2 of 4 is tracking beyond 3 sigma
    assert confident_wrong_fraction([_fake(e, s, ["lost"] * 4)]) == 0.0


def _cfg(**over):
    base = {"trajectory.steps": 200, "filter.particles": 300}
    return apply_overrides(config_from_dict({}), {**base, **over})


def test_nominal_episode_tracks_with_a_2_sigma_spread():
    res = [run_episode(_cfg(), seed) for seed in (0, 1)]
    m = metrics(res)
    assert sum(m["status_counts"].values()) == 400
    assert m["status_counts"]["tracking"] >= 0.98 * 400
    cov = m["coverage_2sigma"]
    assert set(cov) == {"x", "y", "z", "rx", "ry", "rz"}
    # the spread is neither far too narrow nor absurdly wide on the default cell
    assert min(cov.values()) >= 0.7 and np.mean(list(cov.values())) >= 0.85
    assert m["spread_median_mm"]["x"] < 0.3
    assert m["confident_wrong"] == confident_wrong_fraction(res) <= 0.02


@pytest.mark.parametrize("kind", ["xy", "yz"])
def test_nominal_2_sigma_coverage_is_honest_on_every_axis(kind):
    # issue 15 deliverable 2: over 60 default episodes (500 particles, 500 steps) the 2-sigma coverage asked is
    # in [0.9, 0.99] on all six axes, the paper's two seams; the walk per tool axis (filter.axis_scale_*,
    # load_axis_scale_*) is what brings x (and on yz the roll and yaw) down from 0.999-1.0: the isotropic
    # walk of the paper's eq. 3 is checked on 10 of the episodes. 60, not 30: one axis's coverage moves by
    # +-0.005-0.01 between sets of 30. Seeds 0-59: xy 0.963-0.981, yz 0.955-0.981 (confident wrong 0.58 / 0.74 %),
    # with the compliance model, the particles' noise in the bound and the report scaled to the error of the bound's
    # gain under bound_drift_share 0.5 (without the last: every axis 0.99-1.0 once the compliance was modelled;
    # before the model xy 0.968-0.985). A run that never lost the track keeps the bound at the true sigma
    cfg = apply_overrides(config_from_dict({}), {"trajectory.kind": kind})
    res = [run_episode(cfg, seed) for seed in range(60)]
    m = metrics(res)
    cov = np.array([m["coverage_2sigma"][a] for a in ("x", "y", "z", "rx", "ry", "rz")])
    assert cov.min() >= 0.9 and cov.max() <= 0.99, cov
    assert m["status_counts"]["tracking"] >= 0.98 * 60 * 500
    if kind == "xy":
        # no yaw bias once the tool passes a peak of the wave (steps 300-350: the mean of error / spread over
        # the episodes was -1.0 with the seam model 0.02 mm off, trend_eps_mm; -0.2 over 10 episodes now)
        z = np.stack([r.error[300:350, 5] / r.spread[300:350, 5] for r in res])
        assert abs(z.mean()) < 0.5, z.mean()
    assert m["confident_wrong"] <= 0.015
    iso = apply_overrides(cfg, {"filter.axis_scale_t": [1.0, 1.0, 1.0], "filter.axis_scale_r": [1.0, 1.0, 1.0],
                                "filter.load_axis_scale_r": [1.0, 1.0, 1.0]})
    cov_iso = integrity_summary([run_episode(iso, seed) for seed in range(10)])[0]
    assert cov_iso[0] > 0.99  # x too wide with one width for all axes


def test_after_a_wrong_start_at_most_5_percent_of_the_steps_beyond_3_sigma_are_tracking():
    # issue 15 deliverable 1 on the bundled stress-wrong-start.yaml (the first cloud 8 mm / 3 deg off per axis, outside
    # the robot plateau), 60 episodes: measured 0.0 % (0.4 / 0.5 % on seeds 0-179 / 180-359; before the compliance
    # model 0.7 %, 1.4 / 2.5 %); 6.9 % then when the bound's
    # inflation after a loss lasted 200 steps and the spread had no shrink limit (the late tails came 200-480 steps
    # after the loss, where a corner's information cut the spread faster than the estimate moved); the lost phase
    # itself is flagged
    cfg = load_config(Path(__file__).resolve().parents[2] / "examples" / "seam" / "stress-wrong-start.yaml")
    res = [run_episode(cfg, seed) for seed in range(60)]
    cov, counts, beyond = integrity_summary(res)
    assert counts["lost"] >= 60 and beyond is not None
    assert beyond <= 0.05, beyond
    assert counts["tracking"] >= 0.9 * 60 * 500  # and then it tracks


def test_compliance_ten_times_the_model_is_never_reported_tracking():
    cfg = _cfg(**{"process.joint_compliance_rad_per_nm": 1e-5, "process.cartesian_compliance_mm_per_n": 1e-3,
                  "process.cartesian_compliance_deg_per_n": 5e-3, "trajectory.steps": 100})
    r = run_episode(cfg, 0)
    cov, counts, beyond = integrity_summary([r])
    assert beyond is not None and beyond <= 0.05
    assert counts["tracking"] <= 0.05 * 100
    assert all(x is not None for x, s in zip(r.reason, r.status) if s != "tracking")


def test_wrong_start_outside_the_prior_is_flagged_then_recovers():
    cfg = _cfg(**{"filter.init_offset_mm": [3.0, 3.0, 3.0], "filter.init_offset_deg": [1.2, 1.2, 1.2],
                  "trajectory.steps": 60})
    r = run_episode(cfg, 0)
    assert r.status[0] == "lost"
    # the lasers pull the cloud onto the seam: tracking again, and then honestly so
    assert (r.status[-20:] == "tracking").all()
    assert np.all(np.abs(r.error[-20:]) <= 3 * r.spread[-20:] + 1e-9) or integrity_summary([r])[2] is not None


def test_estimates_csv_carries_status_and_the_six_spreads(tmp_path):
    from posekit.seam.frontend.report import read_estimates_csv, write_estimates_csv

    r = run_episode(_cfg(**{"trajectory.steps": 20, "filter.particles": 100}), 3)
    back = read_estimates_csv(write_estimates_csv(tmp_path / "estimates.csv", [r, r]))
    assert back["status"].tolist() == r.status.tolist() * 2
    for i, name in enumerate(STATUS_COLUMNS[1:]):
        want = r.spread[:, i] if i < 3 else np.degrees(r.spread[:, i])  # the library's rad -> the *_deg columns
        np.testing.assert_allclose(back[name], np.tile(want, 2), rtol=1e-9)
    assert set(back["status"]) <= {"tracking", "degraded", "lost"}


def test_start_far_outside_the_plateau_is_lost_then_re_acquired_honestly():
    # a start 14 mm / 5 deg off (the plateau here: 5.3 mm / 0.9 deg): the first cloud cannot explain the
    # lasers; lost, then degraded while re-acquiring (filter.integrity_recovery), then tracking with a
    # spread the bound keeps honest (issue 15: a wrong initial pose outside the prior)
    over = {"trajectory.steps": 150, "filter.init_offset_mm": [8.0, 8.0, 8.0],
            "filter.init_offset_deg": [3.0, 3.0, 3.0]}
    r = run_episode(_cfg(**over), 0)
    cov, counts, beyond = integrity_summary([r])
    # (the walk five times wider after a failed step, filter.reacquire_transition_scale: lost for 9-10 steps; 20 at
    # the plain width)
    last = int(np.flatnonzero(r.status == "lost").max())
    assert last < 10 and (r.status[:last + 1] == "lost").all() and (r.status[last + 1:last + 21] == "degraded").all()
    assert r.reason[last + 16] == "re-acquiring: lost 16 step(s) ago"
    assert (r.status[-50:] == "tracking").all()
    assert beyond is not None and beyond <= 0.05
    assert cov.min() >= 0.95  # measured 0.960-0.973, none of its steps beyond 3 sigma tracking
    # without the re-acquiring hold, the bound and the wider walk, the same run's spread is too narrow (measured
    # coverage 0.66-0.85) and the track is lost for 45 steps instead of 10
    old = run_episode(_cfg(**over, **{"filter.integrity_recovery": 0, "filter.spread_bound": 0.0,
                                      "filter.reacquire_transition_scale": 1.0}), 0)
    cov_old, counts_old, _ = integrity_summary([old])
    assert cov_old.min() < 0.8 and counts_old["lost"] > 2 * counts["lost"]


def test_25_kN_is_degraded_beyond_the_plateau_s_measured_range_and_the_walk_does_not_change():
    # issue 15: the default plateau was measured up to 12 kN; at 25 kN it is extrapolated (the truth leaves it
    # in 6 of 30 runs) and no step may be reported tracking. The status is a verdict only: the estimate and the
    # spread are those of the filter without the limit.
    cfg = apply_overrides(config_from_dict({}), {"process.force_n": [490.0, -4900.0, -24500.0],
                                                  "trajectory.steps": 120})
    r = run_episode(cfg, 0)
    free = run_episode(apply_overrides(cfg, {"filter.plateau_max_force_n": 0.0}), 0)
    assert (r.status == "degraded").all()
    assert all(x.endswith("kN the robot plateau was measured at (filter.plateau_max_force_n)") for x in r.reason)
    assert (free.status == "tracking").all()
    np.testing.assert_array_equal(r.estimate, free.estimate)
    np.testing.assert_array_equal(r.spread, free.spread)
    # the default force (5.1 kN, drifting by 20 %) stays inside the range
    nominal = run_episode(_cfg(**{"trajectory.steps": 120}), 0)
    assert (nominal.status == "tracking").mean() >= 0.98


def test_25_kN_the_spread_covers_the_error_where_the_tests_cannot_see_it():
    # issue 15: under 25 kN the truth mostly stays inside the filter's plateau (14 mm / 3.1 deg), so no consistency
    # test can flag the error; with the force-range verdict off (filter.plateau_max_force_n 0) the spread must
    # cover it. The bound running the particles' own random walk (filter.spread_bound 1) and a walk that widens
    # with the travel under load keep the confident-wrong steps (tracking and beyond 3 sigma) under 2 %; the
    # earlier defaults (half the walk in the bound, the raw force rate, no travel terms) give ~10 %.
    previous = {"filter.spread_bound": 0.5, "filter.force_rate_smoothing": 0.0, "filter.k_travel_t_mm_per_mm": 0.0,
                "filter.k_travel_r_deg_per_mm": 0.0, "filter.k_load_travel_t": 0.0, "filter.k_load_travel_r": 0.0,
                "filter.spread_bound_k_travel": 0.03, "filter.reacquire_transition_scale": 1.0}

    def run(over):
        cfg = apply_overrides(config_from_dict({}), {"process.force_n": [490.0, -4900.0, -24500.0],
                                                      "filter.plateau_max_force_n": 0.0, **over})
        res = [run_episode(cfg, seed) for seed in (0, 1)]
        return confident_wrong_fraction(res), integrity_summary(res)[0]

    wrong, cov = run({})
    assert wrong <= 0.02
    assert cov[3] >= 0.9 and cov[4] >= 0.9  # rx, ry
    assert cov.min() >= 0.8
    assert run(previous)[0] > 0.05


def test_bundled_stress_configs_are_the_scenarios_of_the_tests():
    # examples/seam/stress-*.yaml reproduce the issue-15 table from the command line; they must stay the
    # scenarios these tests run (the same overrides on the defaults, nothing else)
    ex = Path(__file__).resolve().parents[2] / "examples" / "seam"
    default = config_from_dict({})
    want = {
        "stress-compliance-x10.yaml": {"process.joint_compliance_rad_per_nm": 1e-5,
                                       "process.cartesian_compliance_mm_per_n": 1e-3,
                                       "process.cartesian_compliance_deg_per_n": 5e-3},
        "stress-25kN.yaml": {"process.force_n": [490.0, -4900.0, -24500.0]},
        "stress-wrong-start.yaml": {"filter.init_offset_mm": [8.0, 8.0, 8.0],
                                    "filter.init_offset_deg": [3.0, 3.0, 3.0]},
    }
    for name, over in want.items():
        assert load_config(ex / name) == apply_overrides(default, over), name
