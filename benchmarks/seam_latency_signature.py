"""Is an undeclared laser latency identifiable from one episode? (issue 26, "Done when": an undeclared latency
should be ``degraded``, not ``tracking``). A measurement, not a feature: its outcome is in docs/notes/issue-26.md.

Run from a source checkout (about 1 min)::

    python benchmarks/seam_latency_signature.py [--seeds 100,101,102,103,104,105]

On the independent cell of tests/seam/independent_cell.py (lasers 13 / 17 ms late, and the same cell with its
lasers on time), each held-out episode is tracked with the checked-in profile of
tests/seam/data/independent_cell_profile.yaml with its latencies set to 0 (the latency undeclared). A latency
``L`` puts ``-L ṁ`` on each reading's in-plane lateral residual (``ṁ`` the reading's own rate), so the slope of the
residual on ``ṁ`` (with an intercept and a linear trend; Newey-West standard error, 25 lags) estimates ``-L``. It is
printed, per sensor, for the residual at the filter's estimate and at the kinematic pose, with its t value.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def slope_t(y, x, lags: int = 25) -> tuple[float, float]:
    """OLS slope of ``y`` on ``x`` (with intercept and linear trend) and its t value (Newey-West, ``lags``)."""
    X = np.c_[np.ones_like(x), np.linspace(-1.0, 1.0, len(x)), x]
    ok = np.isfinite(y) & np.isfinite(x)
    X, y = X[ok], y[ok]
    b, *_ = np.linalg.lstsq(X, y, rcond=None)
    u = y - X @ b
    Xu = X * u[:, None]
    S = Xu.T @ Xu
    for lag in range(1, lags + 1):
        G = Xu[lag:].T @ Xu[:-lag]
        S += (1.0 - lag / (lags + 1.0)) * (G + G.T)
    A = np.linalg.inv(X.T @ X)
    V = A @ S @ A
    return float(b[2]), float(b[2] / np.sqrt(V[2, 2]))


def episode_slopes(cell, seed, profile, folder) -> dict:
    """``{"estimate" | "kinematic": [(slope ms, t) per sensor], "tracking", "confident_wrong"}`` of one episode."""
    from posekit.seam.engine import _kernels as _k
    from posekit.seam.engine.ekf import reading_mounts
    from posekit.seam.engine.seamline import SeamLine
    from posekit.seam.frontend.config import cell_from_config
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.tracker import track_log
    from posekit.seam.frontend.tune_fit import _knots, episode_arrays
    from tests.seam import independent_cell as ic

    ep = ic.episode(cell, seed)
    log = read_episode_log(ic.write_episode(folder, cell, ep, declare_latency=False), profile=profile)
    r = track_log(log)
    c = cell_from_config(log.config.cell)
    arr = episode_arrays(log)
    Tn = c.chain.forward_kinematics(log.qref, check=False)
    S = c.n_sensors
    Ms = reading_mounts(c.chain, c.mounts, arr.time_s, arr.q_ref, np.zeros(S), arr.reading_lag_s, Tn)
    pts = SeamLine(_knots(log)).points
    out = {}
    for name, T in (("estimate", np.asarray(r.estimate)), ("kinematic", np.asarray(r.kinematic))):
        rows = []
        for i in range(S):
            m = log.laser_mm[:, i]
            seen = np.isfinite(m[:, 0])
            e = np.full(len(T), np.nan)
            E = np.empty((1, 2))
            for k in np.flatnonzero(seen):
                _k.laser_error_kernel(T[k:k + 1], float(m[k, 0]), float(m[k, 1]), Ms[k, i], pts, 0,
                                      pts.shape[0] - 1, E)
                e[k] = E[0, 0]
            mx = np.interp(np.arange(len(m)), np.flatnonzero(seen), m[seen, 0])
            b, t = slope_t(e, np.gradient(mx, arr.time_s))
            rows.append((1e3 * b, t))
        out[name] = rows
    sc = ic.scores(r.estimate, r.spread, r.status, ep)
    out["tracking"], out["confident_wrong"] = sc["tracking"], sc["confident_wrong"]
    return out


def main(argv=None) -> int:
    from posekit.seam.frontend.profile import load_profile, merge_profile, write_profile
    from tests.seam import independent_cell as ic

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="100,101,102,103,104,105")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        base = load_profile(ROOT / "tests" / "seam" / "data" / "independent_cell_profile.yaml")
        write_profile(root / "zero.yaml", merge_profile(base, {"sensors": [{"latency_s": 0.0}] * 2}))
        print("cell      seed  residual at  sensor 1: slope ms (t)  sensor 2: slope ms (t)  tracking  confident-wrong")
        for label, cell in (("13/17 ms", ic.Cell()), ("on time", ic.Cell(latency_s=(0.0, 0.0)))):
            for s in seeds:
                r = episode_slopes(cell, s, root / "zero.yaml", root / f"{label[:2]}{s}")
                for name in ("estimate", "kinematic"):
                    (b1, t1), (b2, t2) = r[name]
                    print(f"{label:9s} {s:4d}  {name:11s}  {b1:8.1f} ({t1:6.1f})         {b2:8.1f} ({t2:6.1f})"
                          f"          {r['tracking']:.2f}      {r['confident_wrong']:.2f}")
    return 0


if __name__ == "__main__":
    sys.path[:0] = [str(ROOT / "src"), str(ROOT)]
    sys.exit(main())
