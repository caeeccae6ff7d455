"""How much a profile depends on which three episodes it was fitted on (issue 26): a study, not a timing.

Run from a source checkout::

    python benchmarks/seam_training_sets.py --out benchmarks/data/seam_training_sets.json

On the independent cell of the tests (tests/seam/independent_cell.py; lasers 13 / 17 ms late, and on time) it
fits a profile with ``seam tune --with-truth`` on each of the training sets 0-2, 3-5, 6-8 and 9-11 (and 0-5, 6-11:
six episodes) and tracks the same 30 held-out episodes (seeds 100-129) with each: the 2σ coverage per axis, whether every axis lies in the
issue's 0.85-0.99, the tracking share, the confident-wrong share (pooled, worst episode) and the episodes over
5 % confident-wrong. ``benchmarks/seam_validation.py`` scores one training set (0-2) on many scenarios; this
scores many training sets on one. To compare two versions of the tuner, run it with ``PYTHONPATH`` set to the
other checkout's ``src``.
"""

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from seam_validation import AXES, write_json

ROOT = Path(__file__).resolve().parent.parent
SETS = ((0, 1, 2), (3, 4, 5), (6, 7, 8), (9, 10, 11), (0, 1, 2, 3, 4, 5), (6, 7, 8, 9, 10, 11))
HELD_OUT = range(100, 130)
BAND = (0.85, 0.99)


def study(cell, folder: Path) -> list:
    """One row per training set of :data:`SETS` (dicts of the figures above)."""
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.profile import write_profile
    from posekit.seam.frontend.tracker import track_log
    from posekit.seam.frontend.tune import tune_profile
    from tests.seam import independent_cell as ic

    held = {s: ic.episode(cell, s) for s in HELD_OUT}
    dirs = {s: ic.write_episode(folder / f"held{s}", cell, ep, declare_latency=False) for s, ep in held.items()}
    rows = []
    for seeds in SETS:
        train = [ic.write_episode(folder / f"train{s}", cell, ic.episode(cell, s), declare_latency=False)
                 for s in seeds]
        profile = write_profile(folder / "profile.yaml", tune_profile(train, with_truth=True).profile)
        runs = {s: track_log(read_episode_log(dirs[s], profile=profile)) for s in held}
        scores = [ic.scores(r.estimate, r.spread, r.status, held[s]) for s, r in runs.items()]
        cov = np.concatenate([sc["covered"] for sc in scores]).mean(axis=0)
        cw = [sc["confident_wrong"] for sc in scores]
        rows.append({"training_seeds": list(seeds),
                     "coverage_2sigma": {a: round(float(v), 4) for a, v in zip(AXES, cov)},
                     "every_axis_in_band": bool(np.all((cov >= BAND[0]) & (cov <= BAND[1]))),
                     "tracking": round(float(np.mean([sc["tracking"] for sc in scores])), 4),
                     "confident_wrong": round(float(np.mean(cw)), 4),
                     "confident_wrong_worst_episode": round(float(max(cw)), 4),
                     "episodes_confident_wrong_over_5_percent": int(sum(c > 0.05 for c in cw))})
        r = rows[-1]
        print(f"  training {seeds}: {' '.join(f'{v:.3f}' for v in r['coverage_2sigma'].values())} in band "
              f"{r['every_axis_in_band']}, tracking {r['tracking']:.3f}, confident-wrong {r['confident_wrong']:.4f} "
              f"(worst {r['confident_wrong_worst_episode']:.3f}, {r['episodes_confident_wrong_over_5_percent']} "
              "over 5 %)", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="the JSON file to write")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from tests.seam import independent_cell as ic

    t0 = time.time()
    data = {"command": "python benchmarks/seam_training_sets.py --out " + args.out,
            "held_out_seeds": [HELD_OUT.start, HELD_OUT.stop - 1]}
    for label, cell in (("latency 13/17 ms", ic.Cell()), ("on time", ic.Cell(latency_s=(0.0, 0.0)))):
        print(f"independent cell, {label}:", flush=True)
        with tempfile.TemporaryDirectory(prefix="posekit-training-sets-") as tmp:
            data[label] = study(cell, Path(tmp))
    data["seconds"] = round(time.time() - t0, 1)
    write_json(args.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
