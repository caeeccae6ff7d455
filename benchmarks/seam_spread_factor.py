"""How well three training episodes can set the seam filter's spread factor (issue 26): a study, not a timing.

Run from a source checkout::

    python benchmarks/seam_spread_factor.py [--pool 13] [--held 10]

On the independent cell of the tests (tests/seam/independent_cell.py, lasers 13 / 17 ms late) it fits a profile
with ``seam tune --with-truth`` on episodes 0-2, sets every spread factor to 1, and tracks episodes 0..pool-1 (the
pool training sets are drawn from) and 100..100+held-1 (held out). Each episode's ``|error| / spread`` (T, 6) is
kept; a spread factor ``f`` then gives the 2σ coverage ``mean(|e| / s <= 2 f)`` without another run.

It prints, for several rules that set ``f`` per axis from a training set's episodes, the share of all training
sets of 3, 4, 5 and 6 episodes (every subset of the pool) whose held-out coverage lies in the issue's band
0.85-0.99 on every axis, below it on some axis, above it on some axis, and the median coverage per axis:

- ``max p90/2, at least 1``: what ``seam tune`` does (the least factor with which 2σ covers 90 % of every training
  episode's errors, never below the filter's own spread);
- the same without the floor; the pooled 95 % point of ``|e| / s`` over the training episodes (``/ 1.96``);
  that times one standard error of its log (the episodes' spread over √n), and times the one-sided 84 % t point of
  it; a one-sided 95 % prediction bound of a next episode's own factor (log scale); the largest episode's own
  95 % factor.

Last, what no rule can beat: the factor fitted to the pool and the held-out episodes together, and how often a
set of ``held`` episodes drawn from them falls out of the band at that factor.
"""

import argparse
import itertools
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
AXES = ("x", "y", "z", "rx", "ry", "rz")
BAND = (0.85, 0.99)


def _ratios(pool: int, held: int, folder: Path) -> dict:
    """Per episode seed: ``|error| / spread`` (T, 6) of the filter with every spread factor 1."""
    sys.path.insert(0, str(ROOT))
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.profile import merge_profile, write_profile
    from posekit.seam.frontend.tracker import track_log
    from posekit.seam.frontend.tune import tune_profile
    from tests.seam import independent_cell as ic

    cell = ic.Cell()
    train = [ic.write_episode(folder / f"train{s}", cell, ic.episode(cell, s), declare_latency=False)
             for s in (0, 1, 2)]
    fitted = tune_profile(train, with_truth=True).profile
    write_profile(folder / "one.yaml", merge_profile(fitted, {"spread": {a: 1.0 for a in AXES}}))
    out = {}
    for s in [*range(pool), *range(100, 100 + held)]:
        ep = ic.episode(cell, s)
        d = ic.write_episode(folder / f"ep{s}", cell, ep, declare_latency=False)
        r = track_log(read_episode_log(d, profile=folder / "one.yaml"))
        out[s] = np.abs(ic.seam_frame_errors(r.estimate, ep)) / r.spread
    return out


def _rules():
    from scipy.stats import t as student_t

    def per(z, q=95.0):
        return np.array([np.percentile(e, q, axis=0) / 1.96 for e in z])

    def pooled(z):
        return np.percentile(np.concatenate(z), 95.0, axis=0) / 1.96

    def se_log(z):
        return np.std(np.log(per(z)), axis=0, ddof=1) / math.sqrt(len(z))

    def prediction(z):
        lp, n = np.log(per(z)), len(z)
        return np.exp(lp.mean(axis=0) + student_t.ppf(0.95, n - 1) * lp.std(axis=0, ddof=1) * math.sqrt(1 + 1 / n))

    return {
        "max p90/2, at least 1 (seam tune)": lambda z: np.maximum(per(z, 90.0).max(axis=0) * 1.96 / 2.0, 1.0),
        "max p90/2": lambda z: per(z, 90.0).max(axis=0) * 1.96 / 2.0,
        "pooled 95 % point": pooled,
        "pooled x exp(1 se of its log)": lambda z: pooled(z) * np.exp(se_log(z)),
        "pooled x exp(t84 se of its log)": lambda z: pooled(z) * np.exp(student_t.ppf(0.84, len(z) - 1) * se_log(z)),
        "95 % prediction bound of a next episode's": prediction,
        "largest episode's own 95 % factor": lambda z: per(z).max(axis=0),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pool", type=int, default=13, help="episodes training sets are drawn from (default 13)")
    ap.add_argument("--held", type=int, default=10, help="held-out episodes (default 10)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    with tempfile.TemporaryDirectory(prefix="posekit-spread-") as tmp:
        z = _ratios(args.pool, args.held, Path(tmp))
    held = np.concatenate([z[s] for s in range(100, 100 + args.held)])

    def coverage(f):
        return np.mean(held <= 2.0 * f, axis=0)

    np.set_printoptions(precision=3, suppress=True)
    for n in (3, 4, 5, 6):
        sets = list(itertools.combinations(range(args.pool), n))
        print(f"training sets of {n} ({len(sets)}): in band on every axis / below on some / above on some; "
              f"median coverage {' '.join(AXES)}")
        for name, rule in _rules().items():
            c = np.array([coverage(rule([z[s] for s in S])) for S in sets])
            inside = np.all((c >= BAND[0]) & (c <= BAND[1]), axis=1).mean()
            print(f"  {name:44s} {inside:5.2f} {np.any(c < BAND[0], axis=1).mean():5.2f} "
                  f"{np.any(c > BAND[1], axis=1).mean():5.2f}   {np.median(c, axis=0)}")
    everything = [z[s] for s in z]
    oracle = np.percentile(np.concatenate(everything), 95.0, axis=0) / 1.96
    rng = np.random.default_rng(26)
    c = np.array([np.mean(np.concatenate([everything[i] for i in rng.choice(len(everything), args.held, replace=False)])
                          <= 2.0 * oracle, axis=0) for _ in range(2000)])
    print(f"the factor of all {len(everything)} episodes pooled {oracle}: sets of {args.held} of them out of the band "
          f"on some axis {np.any((c < BAND[0]) | (c > BAND[1]), axis=1).mean():.2f}; per-axis 5-95 %: "
          f"{np.percentile(c, 5, axis=0)} - {np.percentile(c, 95, axis=0)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
