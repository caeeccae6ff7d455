"""The seam benchmark (benchmarks/seam.py): its user-written peer computes the same filter step
as posekit, and its rows carry the ``posekit bench`` contract keys. No timing is asserted."""

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from posekit.cli.main import main

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "seam.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("posekit_bench_seam_test", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def scenario(bench):
    # 60 samples: the demo test's trajectory, so a test session computes its IK and knots once
    return bench.Scenario(bench.bench_config(50, steps=60), steps=4)


def test_peer_step_equals_posekit_step(bench, scenario):
    """Zero walk and jitter, no resampling, no tempering, no compliance model: from the same particles both
    filters give the same log-weights, ESS, mean position, (up to chordal vs quaternion mean) mean rotation and
    cloud spread."""
    from posekit.seam.frontend.config import apply_overrides

    cfg = apply_overrides(bench.bench_config(64, steps=60), {
        **{f"profile.walk.{a}": 0.0 for a in ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")},
        **{f"profile.jitter.{a}": 0.0 for a in ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")},
        "filter.ess_threshold": 1e-9, "filter.anneal_stages": 0,
        # the peer's sensors read at the sample's time
        "profile.sensors": [{"latency_s": 0.0, "sigma_mm": 0.05, "angle_sigma_deg": 0.2}],
        # the peer has no compliance model (robot density at Fk(q))
        "cell.compliance_rad_per_nm": 0.0})
    peer = bench.UserStepFilter(cfg, scenario.polyline, scenario.T_start, seed=3)
    ours = bench._filter(cfg, scenario, 0)
    Ts = np.repeat(np.eye(4)[None], 64, axis=0)
    Ts[:, :3, :3] = peer.R.as_matrix()
    Ts[:, :3, 3] = peer.p
    ours.T = Ts
    ours._init_pending = False  # start from the peer's cloud, not from a draw of the robot density
    for inp in scenario.inputs[:3]:
        ours._init_pending = False  # nor a new draw after a lost step (the peer has no integrity tests)
        est = ours.step(inp)
        T_peer, spread_peer, ess_peer = peer.step(inp)
        assert est.lasers_used == 2
        np.testing.assert_allclose(ours.logw, peer.logw, rtol=1e-9, atol=1e-9)
        assert est.ess == pytest.approx(ess_peer, rel=1e-9)
        np.testing.assert_allclose(est.T[:3, 3], T_peer[:3, 3], atol=1e-9)
        np.testing.assert_allclose(est.T[:3, :3], T_peer[:3, :3], atol=1e-6)
        # ours reports at least the information bound (engine/spread_bound.py); the cloud's own spread is the peer's
        np.testing.assert_allclose(ours._cloud(ours.T, ours.weights)[1], spread_peer, rtol=1e-3, atol=1e-6)
        assert np.all(est.spread >= spread_peer * (1 - 1e-3))
        np.testing.assert_allclose(ours.T[:, :3, 3], peer.p, atol=1e-9)


def test_scenario_lasers_see_the_seam(scenario):
    """The scenario's laser readings are the seam's (x, z) in the tool frame where the seam
    crosses y = 20 mm and y = 40 mm (interpolated independently here), plus the sensor noise."""
    assert len(scenario.inputs) == 4
    laser = np.array([inp.laser_mm for inp in scenario.inputs])
    assert laser.shape == (4, 2, 2) and np.all(np.isfinite(laser))
    seam = scenario.nominal.seam
    for k, inp in enumerate(scenario.inputs):
        T = inp.T_nominal
        local = (seam - T[:3, 3]) @ T[:3, :3]           # seam points in the tool frame, mm
        for i, d in enumerate((20.0, 40.0)):
            j = np.flatnonzero(np.diff(np.sign(local[:, 1] - d)) != 0)[0]
            g = (d - local[j, 1]) / (local[j + 1, 1] - local[j, 1])
            expect = local[j, [0, 2]] + g * (local[j + 1, [0, 2]] - local[j, [0, 2]])
            np.testing.assert_allclose(laser[k, i], expect, atol=5 * scenario.cfg.simulation.laser_noise_mm)
    assert abs(laser[0, 0, 0]) > 10.0     # at the start the xy wave is well off the tool's straight line


def test_bench_rows_contract(bench, capsys):
    rows = bench.run(count=3, verbose=True, sizes=(40, 80))
    out = capsys.readouterr().out
    assert "posekit bench seam" in out and "target: <= 1 ms per step at N = 1,000" in out
    assert [r["name"] for r in rows] == ["seam.step.N40", "seam.step.N80", "seam.tracker.N80"]
    tracker = rows.pop()
    assert {"ours_ms", "ours_p99_ms", "baseline_ms", "speedup", "realtime_factor"} <= set(tracker)
    assert tracker["ours_p99_ms"] >= tracker["ours_ms"] and tracker["steps"] == 3
    assert "SeamTracker.step" in out and "p99" in out
    for r in rows:
        assert {"name", "ours_ms", "baseline", "baseline_ms", "speedup", "realtime_factor",
                "realtime_factor_1khz", "ours_shipped_ms", "shipped_tempered_steps"} <= set(r)
        assert r["speedup"] == pytest.approx(r["baseline_ms"] / r["ours_ms"])
        assert r["realtime_factor"] == pytest.approx(10.0 / r["ours_ms"])
        assert r["realtime_factor_1khz"] == pytest.approx(1.0 / r["ours_ms"])
        assert r["sensors"] == 2 and r["steps"] == 3
        assert math.isfinite(r["ours_median_error_mm"]) and r["ours_median_error_mm"] < 5.0
        json.dumps(r)


def test_bench_cli_knows_seam(capsys):
    from posekit.cli.bench import BENCHMARKS
    assert "seam" in BENCHMARKS
    rc = main(["bench", "nosuch"])
    assert rc == 2
    assert "'seam'" in capsys.readouterr().err
