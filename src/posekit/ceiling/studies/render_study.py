"""What each realistic effect of the renderer does to the tracker: one row per effect (alone) and
for all of them, against the renderer's truth.

Run ``python -m posekit.ceiling.render_study [--duration-s 30] [--seeds 0,1] [--out DIR]``: it
renders each case (one red dot, the default scene plus one effect of
:data:`~posekit.ceiling.sim.config.REALISTIC`), calibrates from the exact grid points of
``calibration_points.csv`` (undistorted with the simulated lens where the case says
``--camera``), tracks with :func:`~posekit.ceiling.track.pipeline.track_video` and prints a Markdown
table: status counts, the error of ``ok`` rows (mm), ``ok`` rows more than 50 mm off (a lamp
taken for the dot), ``ok`` rows without a visible dot, and visible dots not ``ok``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["CASES", "effect_row", "main"]

#: (name, SceneConfig overrides, undistort with the simulated lens)
CASES = [
    ("clean (mjpg)", {}, True),
    ("codec mp4v", {"codec": "mp4v"}, True),
    ("codec xvid", {"codec": "xvid"}, True),
    ("bloom 1", {"bloom": 1.0}, True),
    ("exposure steps 8 s, ±30 %", {"exposure_step_s": 8.0}, True),
    ("1 occluder", {"occluders": 1}, True),
    ("2 shadows", {"shadows": 2}, True),
    ("1 steady red light", {"stray_lights": 1}, True),
    ("1 blinking red light", {"blinking_lights": 1}, True),
    ("2 reflections", {"reflections": 2}, True),
    ("red LED 100 mm past a vent", {"stray_light_xy_mm": ((2200.0, 900.0),)}, True),
    ("lens k1=-0.2 k2=0.04, no --camera", {"dist": "REALISTIC"}, False),
    ("lens k1=-0.2 k2=0.04, --camera", {"dist": "REALISTIC"}, True),
    ("all realistic, --camera", "REALISTIC", True),
]

HEADER = ("| case | seed | ok | predicted | lost | ok error mean (mm) | p95 | max | ok > 50 mm | ok without dot | "
          "visible, not ok |\n|---|---|---|---|---|---|---|---|---|---|---|")


def effect_row(name: str, overrides, use_camera: bool, *, duration_s: float, seed: int, out_dir) -> str:
    """Render, calibrate, track one case; its Markdown table row."""
    from ..camera.homography import calibrate
    from ..camera.lens import load_camera
    from ..camera.points import read_points_csv, undistort_calibration_points
    from ..sim.config import REALISTIC, SceneConfig
    from ..sim.video import render_video
    from ..track.pipeline import track_video
    from .truth import compare_with_truth, read_truth_csv

    kw = dict(REALISTIC) if overrides == "REALISTIC" else {
        k: (REALISTIC[k] if v == "REALISTIC" else v) for k, v in overrides.items()}
    cfg = SceneConfig(duration_s=duration_s, dots=("red",), seed=seed, **kw)
    paths = render_video(cfg, out_dir)
    pts = read_points_csv(paths.calibration_points)
    cam = load_camera(paths.camera)
    lens = cam if (use_camera and cam.is_distorted) else None
    uv = pts.image_uv if lens is None else undistort_calibration_points(lens, pts.image_uv)
    cal = calibrate(pts.world_xy, uv, rng=0)
    res = track_video(paths.video, cal, ("red",), camera=lens)
    truth = read_truth_csv(paths.truth)
    e = compare_with_truth(res, truth)
    n = min(len(res.rows), len(truth.frame))
    status = res.status()[:n]
    err = np.hypot(*(res.xy()[:n] - truth.xy[:n]).T)
    far = int(np.sum((status == "ok") & (err > 50.0)))
    c, ok = res.counts(), e["ok"]
    return (f"| {name} | {seed} | {c['ok']} | {c['predicted']} | {c['lost']} | {ok.mean_mm:.2f} | {ok.p95_mm:.2f} | "
            f"{ok.max_mm:.1f} | {far} | {e['ok_without_dot']} | {e['visible_not_ok']} |")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m posekit.ceiling.render_study", description=__doc__.split("\n")[0])
    p.add_argument("--duration-s", type=float, default=30.0)
    p.add_argument("--seeds", default="0", help="comma-separated render seeds (default 0)")
    p.add_argument("--cases", default="", help="';'-separated case names (default: all)")
    p.add_argument("--out", default=None, help="keep the renders in this folder (default: a temporary one)")
    a = p.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",")]
    only = [c.strip() for c in a.cases.split(";") if c.strip()]
    print(HEADER, flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(a.out or tmp)
        for k, (name, overrides, cam) in enumerate(CASES):
            if only and name not in only:
                continue
            for seed in seeds:
                print(effect_row(name, overrides, cam, duration_s=a.duration_s, seed=seed,
                                 out_dir=root / f"case{k:02d}_seed{seed}"), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
