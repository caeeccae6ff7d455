"""The issue-15 figures: Fig. 5 measurement hypotheses, ±2σ bands, the ESS/resampling plot, the
design ranking; and the hypotheses themselves against a hand computation."""

import math

import numpy as np

from posekit.geometry import matrix_from_rotation_vector
from posekit.seam.frontend.config import config_from_dict
from posekit.seam.frontend.episode import measurement_hypotheses, run_episode
from posekit.seam.frontend.plots import (
    plot_design_ranking,
    plot_ess,
    plot_measurement_hypotheses,
    plot_tracking_errors,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 5000
    return data


def test_hypotheses_are_the_reading_carried_by_each_particle():
    M = np.eye(4)
    M[:3, :3] = matrix_from_rotation_vector(np.array([0.0, 0.0, math.radians(30.0)]))
    M[:3, 3] = [2.0, 25.0, -1.0]
    T = np.repeat(np.eye(4)[None], 2, axis=0)
    T[1, :3, 3] = [10.0, 0.0, 0.0]
    T[1, :3, :3] = matrix_from_rotation_vector(np.array([0.0, 0.0, math.pi / 2]))
    h = measurement_hypotheses(T, M, [3.0, 4.0])
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    local = np.array([2.0 + 3.0 * c, 25.0 + 3.0 * s, -1.0 + 4.0])   # sensor origin + 3 mm along its x, 4 along z
    assert np.allclose(h[0], local)
    assert np.allclose(h[1], [10.0 - local[1], local[0], local[2]])   # turned 90° about z, shifted 10 mm in x


def test_run_episode_records_a_snapshot_at_the_corner_and_figures_draw(tmp_path):
    cfg = config_from_dict({"trajectory": {"kind": "bend", "bend_deg": 90, "tool_orientation": "tangent",
                                           "steps": 80, "length_mm": 80.0}, "filter": {"particles": 120}})
    r = run_episode(cfg, 2, record_particles=20)
    plain = run_episode(cfg, 2)
    assert np.array_equal(r.estimate, plain.estimate)           # recording does not change the run
    snap = r.snapshot
    assert plain.snapshot is None and snap["step"] == int(np.searchsorted(r.t_s * 0 + np.linspace(0, 80, 80), 40.0))
    assert snap["hypotheses"].shape == (120, 3) and np.all(np.isfinite(snap["loglik"]))
    # the hypotheses lie near the seam point the true pose implies (within the cloud's few mm)
    assert np.median(np.linalg.norm(snap["hypotheses"] - snap["truth_point"], axis=1)) < 3.0
    _png(plot_measurement_hypotheses(snap, r.seam, tmp_path / "h.png"))
    err = r.error[None]
    _png(plot_tracking_errors(err, r.kinematic_error[None], tmp_path / "e.png", t_s=r.t_s, spread=r.spread[None]))
    _png(plot_ess(r.ess, r.resampled, 120, tmp_path / "ess.png", t_s=r.t_s, status=r.status))


def test_design_ranking_figure(tmp_path):
    rows = [{"sensors": 2, "distances_mm": "20;40", "angle": 0, "score": 0.5, "rmse_x_mm": 0.1, "rmse_y_mm": 0.1,
             "rmse_z_mm": 0.1, "kinematic_score": 2.8},
            {"sensors": 0, "distances_mm": "", "angle": 0, "score": 2.8, "rmse_x_mm": 1.0, "rmse_y_mm": 1.0,
             "rmse_z_mm": 1.5, "kinematic_score": 2.8}]
    _png(plot_design_ranking(rows, tmp_path / "r.png"))
