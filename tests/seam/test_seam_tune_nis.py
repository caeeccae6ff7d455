"""``seam tune``'s calibration of the integrity test (frontend/tune_nis.py) on series written here with a known
mean and known effective degrees of freedom, and its effect on a cell posekit did not simulate."""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from posekit.seam.frontend.tune_nis import calibrate_components


def _ar1_squares(rng, c, phi, n):
    """``c z²`` with ``z`` a unit-variance Gaussian AR(1) of coefficient ``phi``: mean ``c``; ``z²``'s
    autocorrelation is ``phi^(2k)``, so its integrated autocorrelation time is ``(1 + phi²) / (1 - phi²)`` and, with
    ``var(z²) = 2``, one reading is worth ``(1 - phi²) / (1 + phi²)`` degrees of freedom of a χ²."""
    z = lfilter([math.sqrt(1.0 - phi * phi)], [1.0, -phi], rng.standard_normal(n))
    return c * z * z


@pytest.mark.parametrize("c, phi", [(0.8, 0.0), (1.3, 0.5), (0.6, 0.7)])
def test_mean_and_degrees_of_freedom_of_correlated_squares(c, phi):
    rng = np.random.default_rng(7)
    eps = [_ar1_squares(rng, c, phi, 20_000) for _ in range(3)]
    eps[1][::17] = np.nan                                 # dropped readings are left out, not zeros
    mean, std, rho, rho_std, n = calibrate_components(eps)
    assert n == 60_000 - len(eps[1][::17])
    rho_true = (1.0 - phi ** 2) / (1.0 + phi ** 2)
    assert mean == pytest.approx(c, abs=4.0 * std) and std < 0.05 * c
    # the autocorrelation sum stops below rho_k = 0.05 (posekit._autocorr): a few per cent of bias at most
    assert rho == pytest.approx(rho_true, rel=0.1)
    assert 0.0 < rho_std < 0.1 * rho and abs(rho - rho_true) < 0.05 + 5.0 * rho_std      # the episodes agree


def test_heavier_tails_than_chi2_are_fewer_degrees_of_freedom():
    # u = c t_5² / (5/3): mean c, var(u/c) = 2 (1 + 3/(5-4)) = 8 for a t with 5 dof: worth a quarter of a chi2_1 each
    rng = np.random.default_rng(3)
    eps = [0.9 * rng.standard_t(5, 100_000) ** 2 / (5.0 / 3.0) for _ in range(2)]
    mean, _, rho, _, _ = calibrate_components(eps)
    assert mean == pytest.approx(0.9, rel=0.05)
    assert rho == pytest.approx(0.25, rel=0.3)    # the sample variance of a t_5² converges slowly


def test_episodes_whose_means_spread_wider_than_their_autocorrelation_says_are_worth_fewer_dof():
    """Each episode white χ²₁ (ρ = 1 within it) times its own level, 1 ± 0.2 from episode to episode (a wander
    slower than an episode): over 20 episodes of n = 500 the means vary by 0.04 (relative variance), far beyond
    2 / (ρ n) = 0.004, so ρ is what the means' spread says, 2 / (n var) ~ 0.1; homogeneous episodes keep ρ ~ 1."""
    rng = np.random.default_rng(11)
    levels = 1.0 + 0.2 * rng.standard_normal(20)
    eps = [lv * rng.standard_normal(500) ** 2 for lv in levels]
    mean, std, rho, rho_std, _ = calibrate_components(eps)
    m = np.array([e.mean() for e in eps]) / mean
    assert rho == pytest.approx(2.0 / (500 * np.var(m, ddof=1)), rel=1e-9) and 0.03 < rho < 0.3
    assert rho_std == pytest.approx(rho * math.sqrt(2.0 / 19)) and std >= mean * math.sqrt(2.0 / (rho * 10_000))
    same = [rng.standard_normal(500) ** 2 for _ in range(20)]
    assert calibrate_components(same)[2] == pytest.approx(1.0, rel=0.15)


def test_too_few_readings_give_nothing():
    assert all(math.isnan(v) for v in calibrate_components([np.array([np.nan, 1.0])])[:4])
    assert calibrate_components([np.array([np.nan, 1.0])])[4] == 1


def test_an_unpinned_latency_s_pose_shift_sets_the_spread_factor(monkeypatch):
    """frontend/tune_latency.py on a filter replaced by a stand-in whose estimate moves 2 mm along x per 10 ms of
    latency with a spread of 1 mm: the factor is √(1 + (Δ/2)²) on x, 1 elsewhere, capped at the profile's 100."""
    from types import SimpleNamespace

    from posekit.seam.frontend import tune_latency
    from posekit.seam.frontend.profile import default_profile
    from posekit.seam.frontend.tune import TunedValue
    from posekit.seam.frontend.tune_filter import FilterRun

    T = 50

    def fake_run(log, profile):
        est = np.tile(np.eye(4), (T, 1, 1))
        est[:, 0, 3] = log.mm_per_s * float(np.asarray(profile.latency_s).reshape(-1)[0])
        return FilterRun(est, np.tile(np.eye(4), (T, 1, 1)), np.ones((T, 6)), ["tracking"] * T, np.ones((T, 2)),
                         np.ones((T, 2)))

    monkeypatch.setattr(tune_latency, "run_filter", fake_run)
    got = {}

    def put(key, value, std, pinned, note=""):
        got[key] = (value, note, std)

    loose = [TunedValue("sensors[0].latency_s", 0.0, None, False, "not pinned", (0.0, 0.01))]
    profile = default_profile().model_copy(update={"sensors": default_profile().sensors[:1]})
    assert tune_latency.latency_spread([SimpleNamespace(time_s=np.zeros(T), mm_per_s=200.0)], profile, loose, put)
    kept = float(profile.sensors[0].latency_s)                              # the profile's, ~0.4 µs
    assert got["spread.x"][0] == pytest.approx(math.sqrt(1.0 + (200.0 * (0.01 - kept) / 2.0) ** 2), rel=1e-12)
    assert [got[f"spread.{a}"][0] for a in ("y", "z", "rx", "ry", "rz")] == [1.0] * 5
    assert "sensors[0] at 10.0 ms" in got["spread.x"][1] and got["spread.x"][2] is None    # one episode: no 1σ
    two = [SimpleNamespace(time_s=np.zeros(T), mm_per_s=v) for v in (200.0, 400.0)]          # Δ = 2 and 4 mm
    assert tune_latency.latency_spread(two, profile, loose, put)
    f1, f2 = (math.sqrt(1.0 + (v * (0.01 - kept) / 2.0) ** 2) for v in (200.0, 400.0))
    assert got["spread.x"][0] == pytest.approx(f2, rel=1e-12)                                # the larger need
    assert got["spread.x"][2] == pytest.approx(abs(f2 - f1) / math.sqrt(2.0) / math.sqrt(2.0), rel=1e-9)
    assert tune_latency.latency_spread([SimpleNamespace(time_s=np.zeros(T), mm_per_s=1e5)], profile, loose, put)
    assert got["spread.x"][0] == 100.0 and "capped; declare the latency" in got["spread.x"][1]
    # a pinned latency leaves the factors alone
    assert not tune_latency.latency_spread([], profile, [TunedValue("sensors[0].latency_s", 0.01, 1e-4, True)], put)
