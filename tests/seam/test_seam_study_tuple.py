"""``study`` with tuple keys as factors (issue 15): a whole tuple scaled by its draw, or one item."""

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.study import seam_study
from posekit.seam.frontend.study_factors import factor_value, get_dotted, make_factors, set_dotted, study_base
from tests.cli_helpers import assert_one_line_error, run_cli


def test_tuple_keys_and_items():
    base = study_base(config_from_dict({"cell": {"sensors": {"distances_mm": [20, 40]}}}))
    f = make_factors(base, ["cell.sensors.distances_mm", "simulation.force_n", "simulation.force_n[2]"], spread=0.25)
    assert [(x.name, x.low, x.high) for x in f] == [("cell.sensors.distances_mm", 0.75, 1.25),
                                                    ("simulation.force_n", 0.75, 1.25),
                                                    ("simulation.force_n[2]", -6250.0, -3750.0)]
    assert factor_value(base, "cell.sensors.distances_mm", 1.5) == [30.0, 60.0]
    assert factor_value(base, "simulation.force_n[2]", -4000.0) == -4000.0
    data = {"simulation": {"force_n": [1.0, 2.0, 3.0]}}
    set_dotted(data, "simulation.force_n[1]", 9.0)
    assert data["simulation"]["force_n"] == [1.0, 9.0, 3.0]
    with pytest.raises(ConfigError, match=r"'simulation.force_n' has 3 items; expected an index within them"):
        get_dotted(base, "simulation.force_n[3]")
    with pytest.raises(ConfigError, match="expected a tuple of numbers"):
        make_factors({"a": {"b": ["x"]}}, ["a.b"])


def test_study_with_distance_and_force_factors_draws_them_into_the_runs():
    cfg = config_from_dict({"trajectory": {"steps": 25}, "filter": {"particles": 40},
                            "cell": {"sensors": {"distances_mm": [20, 40]}}})
    factors = make_factors(study_base(cfg), ["cell.sensors.distances_mm", "simulation.force_n[2]"])
    st = seam_study(cfg, runs=4, factors=factors, scheduler="serial", progress=False)
    assert st.status == ["ok"] * 4
    assert np.all((st.X[:, 0] >= 0.5) & (st.X[:, 0] <= 1.5))
    assert np.all((st.X[:, 1] >= -7500) & (st.X[:, 1] <= -2500))
    assert np.all(np.isfinite(st.rmse))


def test_study_cli_refuses_a_range_that_leaves_the_configurations(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "seam", "study", "--parameters", "cell.sensors.distances_mm=0.5:100",
                           "--runs", "2", "--steps", "10", "--particles", "10", "--scheduler", "serial",
                           "--out", tmp_path / "s")
    assert_one_line_error(rc, out, err, "study factor 'cell.sensors.distances_mm': range [0.5, 100] leaves the valid")
