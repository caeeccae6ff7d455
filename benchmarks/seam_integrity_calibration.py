"""The seam integrity monitor's verdicts with the long window calibrated on the profile's own episodes (issue 26).

Run from a source checkout (~2 min on 2 cores)::

    python benchmarks/seam_integrity_calibration.py [--profile tests/seam/data/independent_cell_profile.yaml]
                                                     [--episodes 10]

Prints, per scenario, the share of steps ``tracking``, the 2σ coverage per axis and the confident-wrong share
(``tracking`` while beyond 3σ on some axis) pooled and in the worst episode:

- the independent cell of the tests (tests/seam/independent_cell.py, data posekit's simulator did not make),
  held-out seeds 100.., tracked with the checked-in profile (fitted by ``seam tune --with-truth`` on 3 training
  episodes): latency declared (fitted), undeclared (the same profile claiming 0), lasers on time, encoder
  offsets, force-sensor biases;
- posekit's own simulator with the shipped default profile: xy, yz, a wrong start.

Run it on another tree's source (``PYTHONPATH=OTHER/src``) with that tree's profile for a before/after.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _line(name, statuses, errors, spreads) -> str:
    st = [np.asarray(s) for s in statuses]
    trk = [float(np.mean(s == "tracking")) for s in st]
    cw = [float(np.mean((s == "tracking") & (np.abs(e) > 3.0 * sp).any(axis=1)))
          for s, e, sp in zip(st, errors, spreads)]
    cov = np.mean(np.abs(np.concatenate(errors)) <= 2.0 * np.concatenate(spreads), axis=0)
    return (f"{name:28s} tracking {np.mean(trk):.3f} (min {min(trk):.2f})  confident-wrong {np.mean(cw):.4f} "
            f"(worst {max(cw):.3f}, {sum(c > 0.05 for c in cw)} over 5 %)  coverage {np.round(cov, 3).tolist()}")


def independent_cell(profile: Path, episodes: int, folder: Path) -> None:
    sys.path.insert(0, str(ROOT))
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.profile import load_profile, merge_profile, write_profile
    from posekit.seam.frontend.tracker import track_log
    from tests.seam import independent_cell as ic

    zero = write_profile(folder / "zero.yaml",
                         merge_profile(load_profile(profile), {"sensors": [{"latency_s": 0.0}] * 2}))
    scen = (("latency declared (fitted)", ic.Cell(), profile, {}),
            ("latency undeclared", ic.Cell(), zero, {}),
            ("on time, profile says 0", ic.Cell(latency_s=(0.0, 0.0)), zero, {}),
            ("encoder 0.05 deg joint 1", ic.Cell(), profile, {"encoder_offset_deg": (0.05, 0, 0, 0, 0, 0)}),
            ("encoder 0.05 deg joint 2", ic.Cell(), profile, {"encoder_offset_deg": (0, 0.05, 0, 0, 0, 0)}),
            ("force bias 300 N x", ic.Cell(), profile, {"force_bias_n": (300.0, 0, 0)}),
            ("force bias 300 N z", ic.Cell(), profile, {"force_bias_n": (0, 0, 300.0)}))
    for k, (name, cell, prof, kw) in enumerate(scen):
        st, err, spr = [], [], []
        for seed in range(100, 100 + episodes):
            ep = ic.episode(cell, seed, **kw)
            d = ic.write_episode(folder / f"s{k}-{seed}", cell, ep, declare_latency=False)
            r = track_log(read_episode_log(d, profile=prof))
            st.append(r.status)
            err.append(ic.seam_frame_errors(r.estimate, ep))
            spr.append(r.spread)
        print("independent  " + _line(name, st, err, spr), flush=True)


def own_simulator(episodes: int) -> None:
    from posekit.seam.frontend.config import apply_overrides, config_from_dict, load_config
    try:
        from posekit.seam.frontend.episode import run_episode
    except ImportError:                                      # a tree before the split of simulate.py
        from posekit.seam.frontend.simulate import run_episode

    for name, cfg in (("xy", apply_overrides(config_from_dict({}), {"trajectory.kind": "xy"})),
                      ("yz", apply_overrides(config_from_dict({}), {"trajectory.kind": "yz"})),
                      ("wrong start", load_config(ROOT / "examples" / "seam" / "stress-wrong-start.yaml"))):
        res = [run_episode(cfg, s) for s in range(episodes)]
        print("own          " + _line(name, [r.status for r in res], [r.error for r in res],
                                      [r.spread for r in res]), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", type=Path, default=ROOT / "tests" / "seam" / "data" / "independent_cell_profile.yaml")
    ap.add_argument("--episodes", type=int, default=10)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="posekit-integrity-") as tmp:
        independent_cell(args.profile.resolve(), args.episodes, Path(tmp))
    own_simulator(args.episodes)
    return 0


if __name__ == "__main__":
    sys.exit(main())
