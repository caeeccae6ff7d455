"""Gauge model: ridges, round trip, bundled gauges."""

import numpy as np
import pytest

from posekit.errors import GaugeError
from posekit.profiler import BUNDLED_GAUGES, bundled_gauge, gauge_from_design, load_gauge
from posekit.profiler.gauge.model import gauge_to_yaml


@pytest.mark.parametrize("name", BUNDLED_GAUGES)
def test_ridges_lie_on_both_faces(name):
    g = bundled_gauge(name)
    assert g.n_corners == int(name.split("-")[1])
    np.testing.assert_array_equal(g.ridge_q[:, 1], 0.0)
    np.testing.assert_array_equal(g.ridge_s[:, 1], 1.0)
    for lam in (-15.0, 0.0, 12.5):
        p = g.ridge_points(np.full(g.n_corners, lam))
        np.testing.assert_allclose(np.sum(g.normals[:-1] * p, axis=1), g.offsets[:-1], atol=1e-9)
        np.testing.assert_allclose(np.sum(g.normals[1:] * p, axis=1), g.offsets[1:], atol=1e-9)
    # the surface is continuous across every ridge
    x = g.ridge_x(3.0)
    np.testing.assert_allclose(g.surface_z(x - 1e-9, 3.0), g.surface_z(x + 1e-9, 3.0), atol=1e-7)


@pytest.mark.parametrize("name", BUNDLED_GAUGES)
def test_bundled_gauges_are_realistic(name):
    g = bundled_gauge(name)
    width = g.x_range[1] - g.x_range[0]
    assert 80 <= width <= 150                    # fits the 163 mm near-range width
    assert g.beta_deg >= 45                      # no face steeper than 45° (paper §III-D)
    if name == "demo-5":
        assert 95 <= width <= 115


def test_yaml_round_trip(tmp_path):
    g = bundled_gauge("demo-7")
    path = tmp_path / "g.yaml"
    path.write_text(gauge_to_yaml(g))
    h = load_gauge(path)
    np.testing.assert_allclose(h.normals, g.normals, atol=1e-11)
    np.testing.assert_allclose(h.ridge_q, g.ridge_q, atol=1e-9)
    np.testing.assert_allclose(h.ridge_s, g.ridge_s, atol=1e-9)
    assert (h.name, h.x_range, h.y_range) == (g.name, g.x_range, g.y_range)


def test_design_reference_values():
    """A roof: faces z = ±0.5 x + ..., ridges at x = ±10, ±20 on y = 0, skewed by u = dx/dy.

    Its cross-section at y = 0 is symmetric, so it is only usable with a known mounting.
    """
    g = gauge_from_design("roof", [-20, -10, 10, 20], [1.0, 0.5, 0.0, -0.5, -1.0], [0.1, -0.1, 0.1, -0.1],
                          mounting="normal")
    np.testing.assert_allclose(g.ridge_q[:, 0], [-20, -10, 10, 20])
    np.testing.assert_allclose(g.ridge_s[:, 0], [0.1, -0.1, 0.1, -0.1])
    assert g.beta_deg == pytest.approx(45.0)
    np.testing.assert_allclose(g.ridge_q[:, 2].mean(), 20.0)
    assert g.tolerance_um == 0.0
    assert g.ambiguity.startswith("its cross-section is symmetric under a 180° turn about the vertical")


def test_parallel_ridges_are_refused():
    """All ridges along y: a shift along them leaves every profile unchanged (no mounting helps)."""
    msg = ("design: gauge 'roof': all 4 ridges are parallel (direction [u, 1, w] = [0.0, 1.0, 0.0]); a shift of the "
           "sensor along them leaves every profile unchanged, so the profiles cannot tell those poses apart; "
           "skew at least one ridge")
    for mounting in ("auto", "normal"):
        with pytest.raises(GaugeError) as exc:
            gauge_from_design("roof", [-20, -10, 10, 20], [1.0, 0.5, 0.0, -0.5, -1.0], [0, 0, 0, 0],
                              mounting=mounting)
        assert str(exc.value) == msg


def test_tolerance_round_trip_and_bad_values(tmp_path):
    g = bundled_gauge("demo-5")
    assert g.tolerance_um == 0.0
    text = gauge_to_yaml(g)
    assert "tolerance_um" not in text                  # an exact drawing writes no tolerance
    path = tmp_path / "g.yaml"
    path.write_text(text + "tolerance_um: 12.5\n")
    h = load_gauge(path)
    assert h.tolerance_um == 12.5
    assert "tolerance_um: 12.5" in gauge_to_yaml(h)
    path.write_text(text + "tolerance_um: -1\n")
    with pytest.raises(GaugeError, match=r"g\.yaml: gauge 'demo-5': tolerance_um must be a finite number >= 0 "
                                         r"\(µm\), got -1\.0$"):
        load_gauge(path)
    path.write_text(text + "tolerance_um: five\n")
    with pytest.raises(GaugeError, match=r"g\.yaml: key 'tolerance_um': "):
        load_gauge(path)
    with pytest.raises(GaugeError, match=r"g\.yaml: unknown mounting 'upside'; expected one of auto, normal, "
                                         r"reversed"):
        load_gauge(path, mounting="upside")


def test_design_rejects_crossing_ridges():
    with pytest.raises(GaugeError, match="faces do not meet in order: at y = -25 mm ridge 1"):
        gauge_from_design("x", [-10, -9, 0, 10], [0.5, -0.5, 0.5, -0.5, 0.5], [-0.5, 0.5, 0, 0])
