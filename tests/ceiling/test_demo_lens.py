"""``posekit ceiling demo`` with a distorting lens: the lens is calibrated from rendered chessboard
views (as a user would with ``posekit ceiling camera``), then the grid and the dots go through it."""

import re

from posekit.ceiling.sim.config import REALISTIC, SceneConfig
from posekit.ceiling.studies.demo import run_demo


def test_demo_with_a_distorting_lens_calibrates_it_from_chessboards(tmp_path):
    cfg = SceneConfig(dist=REALISTIC["dist"], width_px=432, height_px=240, focal_px=185.0)   # half resolution
    rep = run_demo(tmp_path, dots=("red",), seconds=2.0, config=cfg, known_points=False)
    assert re.match(r"calibrated from (9|10|11|12) rendered chessboard views \(rms 0\.\d+ px, k1 -0\.(19|20)", rep.lens_method)
    assert (tmp_path / "camera_calibrated.json").exists()
    assert rep.errors["ok"].n >= 25
    assert rep.errors["ok"].mean_mm < 2.0
    assert "through the lens model" in rep.calibration_method
