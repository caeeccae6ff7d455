"""``posekit ceiling demo``: the §III-C dotted line, the lens calibrated from rendered chessboards,
and report.html with the paper's Figs. 5-9."""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from posekit.ceiling.sim.config import SceneConfig
from posekit.ceiling.sim.render import CeilingScene
from posekit.ceiling.studies.demo import run_demo
from posekit.ceiling.track.linetrack import DottedLineDetector, dots_to_line


def test_dots_to_line_picks_the_row():
    row = np.column_stack([np.arange(5) * 12.0 + 100, np.arange(5) * 3.0 + 50])
    clutter = np.array([[300.0, 40.0], [110.0, 90.0]])
    ends, members = dots_to_line(np.vstack([clutter, row[[0, 1, 3, 4]]]))        # one dot lost in a vent
    assert list(members) == [2, 3, 4, 5]
    assert_allclose(ends, row[[0, 4]], atol=1e-9)
    assert dots_to_line(np.array([[1.0, 2.0]])) is None
    assert dots_to_line(np.vstack([row[:2], [[400.0, 400.0]]]), min_dots=3) is None


def test_dotted_line_detector_on_rendered_frames():
    cfg = SceneConfig(dots=("line",), line_pattern="dotted", duration_s=2.0, holes=False)
    scene = CeilingScene(cfg)
    truth = scene.truth()
    det = DottedLineDetector()
    for k in range(8):
        lines = det.detect(scene.render_frame(k))
    assert len(det.last_dots) == cfg.line_dots
    (line,) = lines
    heading = truth.heading_rad[7]
    ends_true = scene.project(truth.xy_red[7] + np.outer([-0.5, 0.5], [np.cos(heading), np.sin(heading)])
                              * cfg.line_length_mm)
    centre = ends_true.mean(axis=0)
    assert np.hypot(line.u - centre[0], line.v - centre[1]) < 0.5
    d = ends_true[1] - ends_true[0]
    assert line.angle_deg == pytest.approx(np.degrees(np.arctan2(d[1], d[0])) % 180, abs=1.0)
    assert line.length_px == pytest.approx(np.hypot(*d), rel=0.03)


@pytest.fixture(scope="module")
def line_demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo_line")
    return run_demo(out, dots=("line",), seconds=2.0, known_points=False)


def test_demo_dotted_line_tracks_position_and_heading(line_demo):
    e = line_demo.errors
    assert line_demo.counts["ok"] >= 22
    assert e["ok"].mean_mm < 2.0 and e["ok"].max_mm < 10.0
    assert e["heading"]["n"] > 20 and e["heading"]["max_abs_deg"] < 3.0


def test_demo_report_has_the_papers_figures(line_demo):
    html = (line_demo.out_dir / "report.html").read_text()
    for fig in ("fig5_calibration_check.png", "fig7_heading_simulation.png", "fig8_image_trajectory.png",
                "fig9_world_trajectory.png"):
        assert (line_demo.out_dir / fig).exists()
        assert f'href="{fig}"' in html
    assert "Fig. 5: calibration points" in html and "Fig. 7: heading accuracy" in html
    assert "Position error against the truth" in html
    data = json.loads((line_demo.out_dir / "demo.json").read_text())
    assert data["dots"] == ["line"] and data["lens"] == "none (pinhole camera)"
