"""``posekit seam tune`` without a reference on the independent cell (issue 26): the latency each sensor gets, with
its 95 % interval and verdict, and the held-out filter with that profile.

Run from a source checkout::

    python benchmarks/seam_tune_innovations.py [--episodes 10] [--out FILE.json]

For the cell with lasers 13 / 17 ms late and the same cell on time (tests/seam/independent_cell.py), it writes 3
training episodes (seeds 0-2, 400 steps), fits ``tune_profile(train)`` (the laser innovations only: ``posekit seam
tune train0 train1 train2 --out innovations.yaml``), prints the latencies, laser noises and spread factors, then tracks held-out
episodes (seeds 100 ...) with that profile and prints the 2σ coverage per axis, the share of ``tracking`` steps
and the confident-wrong share (tracking while beyond 3σ on some axis) over all steps and in the worst episode
(the same summary as benchmarks/seam_validation.py). A small version of that study's "innovations-fitted
profile" rows; run it with ``PYTHONPATH=OTHER/src`` to measure another version of posekit.
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))


def main(argv=None) -> int:
    from seam_validation import _summary

    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.profile import write_profile
    from posekit.seam.frontend.tracker import track_log
    from posekit.seam.frontend.tune import tune_profile, tune_report
    from tests.seam import independent_cell as ic

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10, help="held-out episodes per cell (default 10)")
    ap.add_argument("--out", help="write the numbers to this JSON file")
    args = ap.parse_args(argv)
    out = {"command": "python benchmarks/seam_tune_innovations.py --episodes " + str(args.episodes)}
    with tempfile.TemporaryDirectory(prefix="posekit-tune-innov-") as tmp:
        for label, cell in (("latency 13/17 ms", ic.Cell()), ("on time", ic.Cell(latency_s=(0.0, 0.0)))):
            root = Path(tmp) / label.replace(" ", "_").replace("/", "-")
            train = [ic.write_episode(root / f"train{s}", cell, ic.episode(cell, s), declare_latency=False)
                     for s in (0, 1, 2)]
            t0 = time.time()
            res = tune_profile(train)
            tune_s = time.time() - t0
            write_profile(root / "innovations.yaml", res.profile)
            lines = [ln for ln in tune_report(res).splitlines() if "latency_s" in ln or "sigma_mm" in ln or "spread." in ln]
            lat = [{"value_ms": round(v.value * 1e3, 3), "pinned": bool(v.pinned),
                    "std_ms": None if v.std is None else round(v.std * 1e3, 3),
                    "interval_ms": None if getattr(v, "interval", None) is None else [round(1e3 * a, 2) for a in v.interval]}
                   for v in res.values if v.key.endswith("latency_s")]
            errs, spr, sts = [], [], []
            for s in range(100, 100 + args.episodes):
                ep = ic.episode(cell, s)
                d = ic.write_episode(root / f"held{s}", cell, ep, declare_latency=False)
                r = track_log(read_episode_log(d, profile=root / "innovations.yaml"))
                errs.append(ic.seam_frame_errors(r.estimate, ep))
                spr.append(r.spread)
                sts.append(r.status)
            summ = _summary(errs, spr, sts)
            med = np.median(np.concatenate(spr), axis=0)
            summ["median_spread"] = {a: round(float(v), 4) for a, v in zip(("x_mm", "y_mm", "z_mm"), med[:3])} | {
                a: round(float(np.degrees(v)), 4) for a, v in zip(("rx_deg", "ry_deg", "rz_deg"), med[3:])}
            out[label] = {"true_latency_ms": [1e3 * x for x in cell.latency_s], "tuned_latency": lat,
                          "tune_seconds": round(tune_s, 1), "report": lines, **summ}
            print(f"{label}: tune {tune_s:.0f} s\n" + "\n".join(lines))
            print(f"  held-out {args.episodes}: coverage {summ['coverage_2sigma']} tracking {summ['tracking']} "
                  f"confident-wrong {summ['confident_wrong']} (worst episode "
                  f"{summ['confident_wrong_worst_episode']}); rmse {summ['rmse_mm']} {summ['rmse_deg']}; median "
                  f"spread {summ['median_spread']}", flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
