"""Figures and report files of the seam front end (posekit.seam.frontend.plots / posekit.seam.frontend.report).

Synthetic arrays in the EpisodeResult shapes; the figures must be real PNGs of the expected
pixel size with content, and the histogram behind Fig. 5 must put the particles where they are.
"""

import base64
import struct
from types import SimpleNamespace

import numpy as np
import pytest

from posekit.errors import ConfigError
from posekit.geometry import se3_exp
from posekit.seam.frontend.plots import (
    particle_histogram,
    plot_error_distributions,
    plot_particle_density,
    plot_pvalue_heatmap,
    plot_tool_paths,
    plot_tracking_errors,
    positions_in_frame,
)
from posekit.seam.frontend.report import (
    ESTIMATE_COLUMNS,
    html_figure,
    html_table,
    read_estimates_csv,
    write_estimates_csv,
    write_html,
    write_json,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: A 1×1 PNG.
TINY_PNG = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5ErkJggg==")


def png_size(path):
    """(width, height) from the IHDR chunk."""
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    return struct.unpack(">II", data[16:24])


def png_pixels(path):
    import matplotlib.image as mpimg
    return mpimg.imread(path)


def check_png(path, size, min_bytes=15_000):
    assert path.is_file()
    assert png_size(path) == size
    assert path.stat().st_size > min_bytes
    img = png_pixels(path)
    assert img[..., :3].std() > 0.05           # not a blank canvas


def test_particle_histogram_puts_particles_in_their_bins():
    edges = np.linspace(0.0, 10.0, 11)
    values = np.array([[0.5, 0.5, 9.5, np.nan], [3.2, 3.7, 3.9, 3.1], [-5.0, 20.0, 5.0, 5.5]])
    h = particle_histogram(values, edges)
    assert h.shape == (3, 10)
    np.testing.assert_allclose(h.sum(axis=1), 1.0)
    np.testing.assert_allclose(h[0, [0, 9]], [2 / 3, 1 / 3])
    assert h[1, 3] == 1.0
    np.testing.assert_allclose(h[2, [0, 9, 5]], [0.25, 0.25, 0.5])   # outside -> end bins


def test_positions_in_frame_start_frame():
    xi = np.zeros((4, 6))
    xi[:, 1] = np.arange(4) * 10.0                      # 10 mm steps along y of the start frame
    T0 = se3_exp(np.array([5.0, -2.0, 1.0, 0.3, -0.2, 0.5]))
    T = T0 @ se3_exp(xi)
    p = positions_in_frame(T)
    np.testing.assert_allclose(p, np.c_[np.zeros(4), 10.0 * np.arange(4), np.zeros(4)], atol=1e-9)


def test_fig5_density_png(tmp_path):
    rng = np.random.default_rng(0)
    T, K = 40, 50
    truth = np.c_[np.linspace(0, 5, T)[:, None] * np.ones((1, 3)), 0.1 * np.ones((T, 3))]
    spread = np.linspace(3.0, 0.3, T)[:, None, None]             # the density narrows over time
    particles = truth[:, None, :] + spread * rng.standard_normal((T, K, 6))
    path = plot_particle_density(particles, truth, tmp_path / "fig5.png", bins=30)
    check_png(path, (1100, 800))
    with pytest.raises(ConfigError, match=r"expected particles \(T, K, 6\) and truth \(T, 6\), got \(40, 50, 6\) "
                                          r"and \(39, 6\)"):
        plot_particle_density(particles, truth[1:], tmp_path / "bad.png")


def test_fig8_bad_groups_and_fig6_heatmap_png(tmp_path):
    """(Fig. 8 with six groups, Fig. 9 and the error traces: test_simulation_report_with_comparison.)"""
    rng = np.random.default_rng(1)
    with pytest.raises(ConfigError, match="group 'bad' must be \\(M, 6\\), got \\(3, 5\\)"):
        plot_error_distributions({"bad": np.zeros((3, 5))}, tmp_path / "x.png")
    with pytest.raises(ConfigError, match="'xy' must be \\(T, 3\\) positions, got \\(4, 2\\)"):
        plot_tool_paths({"xy": np.zeros((4, 2))}, tmp_path / "x.png")
    with pytest.raises(ConfigError, match=r"expected two \(R, T, 6\) error arrays, got \(2, 5, 6\) and \(2, 4, 6\)"):
        plot_tracking_errors(np.zeros((2, 5, 6)), np.zeros((2, 4, 6)), tmp_path / "x.png")
    lp = -np.abs(rng.standard_normal((6, 5))) * 3
    check_png(plot_pvalue_heatmap(lp, list("abcde"), ["x", "y", "z", "rx", "ry", "rz"], tmp_path / "fig6.png"),
              (700, 580), min_bytes=10_000)
    with pytest.raises(ConfigError, match=r"expected log10_p of shape \(6, 4\), got \(6, 5\)"):
        plot_pvalue_heatmap(lp, list("abcd"), ["x", "y", "z", "rx", "ry", "rz"], tmp_path / "x.png")


def _episode(rng, T=12):
    xi = rng.standard_normal((T, 6)) * [10, 10, 10, 0.5, 0.5, 0.5]
    truth = se3_exp(xi)
    est = truth @ se3_exp(0.01 * rng.standard_normal((T, 6)))
    return SimpleNamespace(t_s=0.01 * np.arange(T), truth=truth, estimate=est, nominal=truth.copy(),
                           error=rng.standard_normal((T, 6)), kinematic_error=rng.standard_normal((T, 6)),
                           spread=np.abs(rng.standard_normal((T, 6))), ess=rng.random(T) * 100,
                           step_ms=rng.random(T), status=np.array(["tracking"] * (T - 2) + ["degraded", "lost"]),
                           resampled=rng.random(T) < 0.5, config=SimpleNamespace(filter=SimpleNamespace(particles=100)))


def test_estimates_csv_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    runs = [_episode(rng), _episode(rng, T=7)]
    path = write_estimates_csv(tmp_path / "estimates.csv", runs)
    cols = read_estimates_csv(path)
    assert list(cols) == ESTIMATE_COLUMNS
    assert len(cols["run"]) == 19
    np.testing.assert_array_equal(cols["run"], [0] * 12 + [1] * 7)
    np.testing.assert_array_equal(cols["step"], [*range(12), *range(7)])
    # EpisodeResult rotations are radians; the CSV's *_deg columns hold degrees
    np.testing.assert_allclose(cols["err_rz_deg"], np.degrees(np.r_[runs[0].error[:, 5], runs[1].error[:, 5]]),
                               rtol=1e-9)
    np.testing.assert_allclose(cols["spread_ry_deg"][:12], np.degrees(runs[0].spread[:, 4]), rtol=1e-9)
    np.testing.assert_allclose(cols["std_rx_deg"][12:], np.degrees(runs[1].spread[:, 3]), rtol=1e-9)
    np.testing.assert_allclose(cols["kin_err_y_mm"][:12], runs[0].kinematic_error[:, 1], rtol=1e-9)
    np.testing.assert_allclose(cols["truth_y_mm"][12:], runs[1].truth[:, 1, 3], rtol=1e-9, atol=1e-12)
    # quaternions are unit, scalar first, with qw >= 0, and give back the rotation
    from posekit.geometry import matrix_from_quaternion
    q = np.c_[cols["estimate_qw"], cols["estimate_qx"], cols["estimate_qy"], cols["estimate_qz"]]
    assert np.all(q[:, 0] >= 0)
    R = np.concatenate([r.estimate[:, :3, :3] for r in runs])
    np.testing.assert_allclose(matrix_from_quaternion(q), R, atol=1e-8)


def test_html_report_embeds_figures(tmp_path):
    fig = tmp_path / "fig8.png"
    fig.write_bytes(TINY_PNG)
    write_json(tmp_path / "m.json", {"v": np.float64(1.5), "n": np.int64(3), "nan": float("nan"),
                                     "arr": np.arange(2)})
    import json
    assert json.loads((tmp_path / "m.json").read_text()) == {"v": 1.5, "n": 3, "nan": None, "arr": [0, 1]}
    path = write_html(tmp_path, "T <1>", "<p>intro</p>",
                      [("Fig", html_figure(fig, "caption")),
                       ("Table", html_table([{"a": 1.23456, "b": "x<y"}], ["a", "b"]))])
    text = path.read_text()
    assert path.name == "report.html"
    assert "<title>T &lt;1&gt;</title>" in text
    assert text.count('src="data:image/png;base64,') == 1 and 'href="fig8.png"' in text
    assert "<td>1.235</td><td>x&lt;y</td>" in text


def test_simulation_report_with_comparison(tmp_path):
    """write_simulation with a Fig. 8 grid: metrics.json gains 'comparison', Fig. 9 shows xy and yz."""
    from posekit.seam.frontend.compare import ConfigurationSet
    from posekit.seam.frontend.report import write_simulation

    rng = np.random.default_rng(4)

    def metrics(err):
        r = np.sqrt(np.mean(err ** 2, axis=0))
        return {"rmse_mm": dict(zip("xyz", r[:3])), "rmse_deg": dict(zip(("rx", "ry", "rz"), r[3:])),
                "kinematic_rmse_mm": dict(zip("xyz", 2 * r[:3])),
                "kinematic_rmse_deg": dict(zip(("rx", "ry", "rz"), 2 * r[3:])), "step_ms_median": 0.5}

    sets = []
    for traj in ("xy", "yz"):
        for n in (0, 1, 2):
            res = [_episode(rng, T=15)]
            label = f"{traj}, {n} sensor{'s' if n != 1 else ''}"
            sets.append(ConfigurationSet(label, traj, n, None, res, metrics(res[0].error)))
    main = sets[2]
    paths = write_simulation(tmp_path, main.results, main.metrics, "seed: 0\n", comparison=sets)
    assert set(paths) == {"metrics", "estimates", "config", "fig8", "fig9", "errors", "ess", "report"}   # no particles
    import json
    m = json.loads(paths["metrics"].read_text())
    assert list(m["comparison"]) == [s.label for s in sets]
    assert m["comparison"]["yz, 1 sensor"]["rmse_mm"]["x"] == pytest.approx(sets[4].metrics["rmse_mm"]["x"])
    check_png(paths["fig8"], (1100, 724))   # report width, whatever the number of groups
    check_png(paths["fig9"], (800, 700), min_bytes=10_000)
    check_png(paths["errors"], (1100, 800))
    text = paths["report"].read_text()
    assert text.count('src="data:image/png;base64,') == 4
    assert "<td>yz, 2 sensors</td>" in text and "seed: 0" in text
