"""The robots benchmark (benchmarks/robots.py): its agreement check between posekit and the
Pinocchio peer passes on the bundled arms and fails on a wrong chain. No timing is asserted."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from posekit.cli.bench import BENCHMARKS
from posekit.errors import EstimationError
from posekit.robots import bundled_robot_path, robot_model

pytest.importorskip("pinocchio")

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "robots.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("posekit_bench_robots_test", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["ur10", "abb_irb6640"])
def test_bench_agreement_check(bench, name):
    assert "robots" in BENCHMARKS
    chain = robot_model(name)
    peer = bench.PinocchioPeer(chain, bundled_robot_path(name))
    rng = np.random.default_rng(7)
    Q, QB = bench.sample_q(chain, 5, rng), bench.sample_q(chain, 7, rng)
    err = bench.check_agreement(chain, peer, Q, batch=QB)
    assert err["max_err_t_mm"] <= bench.TOL_T_MM and err["max_rel_err_Jv"] <= bench.TOL_REL
    # the peer's timed call is the raw Pinocchio output (metres, nv columns) of the same pose
    T_pin, J_pin = peer.step(peer.q(Q[:1])[0])
    assert J_pin.shape == (6, peer.model.nv)
    np.testing.assert_allclose(1000.0 * T_pin[:3, 3], chain.forward_kinematics(Q[0])[:3, 3], atol=1e-6)
    # a chain 0.01 mm off its URDF is caught
    wrong = chain.perturbed(0.01, 0.0, np.random.default_rng(1))
    with pytest.raises(EstimationError, match="disagrees with pinocchio"):
        bench.check_agreement(wrong, peer, Q)
