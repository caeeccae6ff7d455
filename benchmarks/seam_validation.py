"""The seam filter's validation study (issue 26): the Monte-Carlo the test suite no longer runs.

Run from a source checkout::

    python benchmarks/seam_validation.py --out benchmarks/data/seam_validation.json [--episodes N]

It writes one JSON file (checked in: ``benchmarks/data/seam_validation.json``) with, per scenario, the 2σ coverage
per axis (share of steps whose |error| <= 2 x the reported spread), the status counts, the confident-wrong share
(steps ``tracking`` while beyond 3σ on some axis) over all steps and the worst single episode's, and what a
perfectly honest spread would show on single episodes with these errors' autocorrelation
(``honest_spread_reference``):

- **posekit's own simulator** (``posekit seam simulate``'s episodes, the shipped default profile, 500 particles,
  500 steps): the paper's xy and yz seams and the bundled stress configurations (wrong start, 25 kN);
- **a cell posekit did not simulate** (tests/seam/independent_cell.py: its own UR10-like arm, seam, deflection,
  drift and two lasers 13 / 17 ms late): ``seam tune --with-truth`` and ``seam tune`` (innovations only) on 3
  training episodes (the latency each recovers, with its 1σ), then held-out episodes tracked with the fitted
  profile (nominal; an encoder offset of 0.05 deg on joint 1 or 2; a force-sensor bias of 300 N along x or z) and
  with the same profile claiming no latency (an undeclared latency); the same on the cell with its lasers on
  time (a profile fitted there); and on both cells with a profile fitted on 9 episodes (enough to pin the
  kinematics' offset, so that the integrity monitor's offset test flags an encoder offset; its latencies, and on
  the late cell the same profile claiming no latency).

The numbers depend on the machine only through floating point; ``--episodes`` sets the episodes per scenario
(default 20 on the own simulator, 30 held-out on the independent cell).
"""

import argparse
import json
import math
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
AXES = ("x", "y", "z", "rx", "ry", "rz")


def _honest_reference(errors, spreads, trials: int = 4000) -> dict:
    """What a perfectly honest spread would show on these episodes: per axis the integrated autocorrelation time
    of ``error / spread`` (median over the episodes, ``posekit._autocorr``), then ``trials`` Monte-Carlo episodes of
    the same length whose six axes are independent unit-variance Gaussian AR(1) series with those times (seeded):
    the probability that more than 5 % of an episode's steps are beyond 3σ on some axis, and the episodes expected
    over 5 % out of these. Errors correlated over tens of steps make single episodes vary far more than the pooled
    share (an honest 2σ leaves 1.6 % of the steps beyond 3σ on some axis, on average)."""
    from posekit._autocorr import autocorrelation_time

    z = [np.asarray(e, dtype=np.float64) / np.asarray(sp, dtype=np.float64) for e, sp in zip(errors, spreads)]
    tau = np.array([np.median([autocorrelation_time(e[:, a]) for e in z]) for a in range(6)])
    phi = (tau - 1.0) / (tau + 1.0)                     # AR(1) with integrated time (1 + φ) / (1 - φ)
    T = int(np.median([len(e) for e in z]))
    rng = np.random.default_rng(26)
    x = rng.standard_normal((trials, 6))
    beyond = np.zeros(trials)
    for _ in range(T):
        x = phi * x + np.sqrt(1.0 - phi ** 2) * rng.standard_normal((trials, 6))
        beyond += np.any(np.abs(x) > 3.0, axis=1)
    p = float(np.mean(beyond / T > 0.05))
    return {"tau_steps": {a: round(float(v), 1) for a, v in zip(AXES, tau)}, "steps": T,
            "p_episode_over_5_percent": round(p, 3), "episodes_over_5_percent_expected": round(p * len(z), 2)}


def _coverage_interval(errors, spreads, resamples: int = 2000) -> dict:
    """Per axis the 90 % interval of the pooled 2σ coverage over these episodes when the episodes themselves are
    resampled (a seeded bootstrap): how far the coverage of another set of as many episodes of the same cell may
    lie. Steps within an episode are correlated over tens of steps, so the episode is the unit."""
    covered = [np.abs(e) <= 2.0 * sp for e, sp in zip(errors, spreads)]
    hits = np.array([c.sum(axis=0) for c in covered], dtype=np.float64)   # (E, 6)
    steps = np.array([len(c) for c in covered], dtype=np.float64)         # (E,)
    rng = np.random.default_rng(26)
    pick = rng.integers(0, len(covered), (resamples, len(covered)))
    cov = hits[pick].sum(axis=1) / steps[pick].sum(axis=1)[:, None]
    lo, hi = np.percentile(cov, [5.0, 95.0], axis=0)
    return {a: [round(float(x), 4), round(float(y), 4)] for a, x, y in zip(AXES, lo, hi)}


def _summary(errors, spreads, statuses) -> dict:
    """Coverage (with its episode-bootstrap 90 % interval), statuses and confident-wrong shares of a list of
    episodes (errors mm/rad, spreads alike)."""
    E = np.abs(np.concatenate(errors))
    S = np.concatenate(spreads)
    st = np.concatenate([np.asarray(s) for s in statuses])
    cw = [float(np.mean((np.asarray(s) == "tracking") & np.any(np.abs(e) > 3.0 * sp, axis=1)))
          for e, sp, s in zip(errors, spreads, statuses)]
    return {"episodes": len(errors), "steps": int(len(st)),
            "coverage_2sigma": {a: round(float(v), 4) for a, v in zip(AXES, np.mean(E <= 2.0 * S, axis=0))},
            "coverage_2sigma_interval_90": _coverage_interval(errors, spreads),
            "status_counts": {k: int(np.sum(st == k)) for k in ("tracking", "degraded", "lost")},
            "tracking": round(float(np.mean(st == "tracking")), 4),
            "confident_wrong": round(float(np.mean((st == "tracking") & np.any(E > 3.0 * S, axis=1))), 4),
            "confident_wrong_worst_episode": round(max(cw), 4),
            "episodes_confident_wrong_over_5_percent": int(sum(c > 0.05 for c in cw)),
            "honest_spread_reference": _honest_reference(errors, spreads),
            "rmse_mm": {a: round(float(v), 4) for a, v in zip(AXES[:3], np.sqrt(np.mean(E[:, :3] ** 2, axis=0)))},
            "rmse_deg": {a: round(math.degrees(float(v)), 4)
                         for a, v in zip(AXES[3:], np.sqrt(np.mean(E[:, 3:] ** 2, axis=0)))}}


def own_simulator(episodes: int) -> dict:
    """The default profile on posekit's own simulated episodes."""
    from posekit.seam.frontend.config import apply_overrides, config_from_dict, load_config
    from posekit.seam.frontend.episode import run_episode

    ex = ROOT / "examples" / "seam"
    scen = {"xy": apply_overrides(config_from_dict({}), {"trajectory.kind": "xy"}),
            "yz": apply_overrides(config_from_dict({}), {"trajectory.kind": "yz"}),
            "stress-wrong-start": load_config(ex / "stress-wrong-start.yaml"),
            "stress-25kN": load_config(ex / "stress-25kN.yaml")}
    out = {}
    for name, cfg in scen.items():
        res = [run_episode(cfg, seed) for seed in range(episodes)]
        out[name] = {"command": f"posekit seam simulate --runs {episodes} --seed 0"
                                + ("" if name in ("xy", "yz") else f" --config examples/seam/{name}.yaml")
                                + (f" --trajectory {name}" if name in ("xy", "yz") else ""),
                     **_summary([r.error for r in res], [r.spread for r in res], [r.status for r in res])}
        print(f"  own {name}: {out[name]['coverage_2sigma']} tracking {out[name]['tracking']} "
              f"confident-wrong {out[name]['confident_wrong']}", flush=True)
    return out


def independent_cell(episodes: int, folder: Path) -> dict:
    """Tune on 3 training episodes of the independent cell, then score held-out ones."""
    sys.path.insert(0, str(ROOT))
    from posekit.seam.frontend.profile import merge_profile, write_profile
    from posekit.seam.frontend.tune import tune_profile
    from tests.seam import independent_cell as ic

    out = {}
    held = range(100, 100 + episodes)
    for label, cell in (("latency 13/17 ms", ic.Cell()), ("on time", ic.Cell(latency_s=(0.0, 0.0)))):
        root = folder / label.replace(" ", "_").replace("/", "-")
        train = [ic.write_episode(root / f"train{s}", cell, ic.episode(cell, s), declare_latency=False)
                 for s in (0, 1, 2)]
        fits = {}
        for method in ("truth", "innovations"):
            res = tune_profile(train, with_truth=method == "truth")
            fits[method] = res
            write_profile(root / f"{method}.yaml", res.profile)
        lat = {m: [{"value_ms": round(v.value * 1e3, 3), "std_ms": None if v.std is None else round(v.std * 1e3, 3)}
                   for v in r.values if v.key.endswith("latency_s")] for m, r in fits.items()}
        block = {"true_latency_ms": [1e3 * x for x in cell.latency_s], "tuned_latency_ms": lat,
                 "command": "posekit seam tune train0 train1 train2 --with-truth --out truth.yaml (and without "
                            "--with-truth: innovations.yaml)"}
        zero = merge_profile(fits["truth"].profile, {"sensors": [{"latency_s": 0.0}] * len(cell.mounts)})
        write_profile(root / "zero-latency.yaml", zero)
        scen = {"nominal": ({}, "truth.yaml"),
                "nominal, innovations-fitted profile": ({}, "innovations.yaml"),
                "encoder offset 0.05 deg joint 1": ({"encoder_offset_deg": (0.05, 0, 0, 0, 0, 0)}, "truth.yaml"),
                "encoder offset 0.05 deg joint 2": ({"encoder_offset_deg": (0, 0.05, 0, 0, 0, 0)}, "truth.yaml"),
                "force-sensor bias 300 N along x": ({"force_bias_n": (300.0, 0, 0)}, "truth.yaml"),
                "force-sensor bias 300 N along z": ({"force_bias_n": (0, 0, 300.0)}, "truth.yaml")}
        if cell.latency_s[0] > 0:
            scen["latency undeclared (profile says 0)"] = ({}, "zero-latency.yaml")
        # a newcomer's first run, before any seam tune: the shipped default profile (fitted on another cell)
        scen["never tuned (the shipped default profile)"] = ({}, None)
        _score(block, label, root, cell, held, scen)
        out[label] = block
    # the offset test needs the kinematics' offset pinned: profiles fitted on 9 episodes of each cell
    for label, cell in (("latency 13/17 ms, profile from 9 episodes", ic.Cell()),
                        ("on time, profile from 9 episodes", ic.Cell(latency_s=(0.0, 0.0)))):
        root = folder / label.replace(" ", "_").replace("/", "-").replace(",", "")
        train = [ic.write_episode(root / f"train{s}", cell, ic.episode(cell, s), declare_latency=False)
                 for s in range(9)]
        fit = tune_profile(train, with_truth=True)
        write_profile(root / "truth.yaml", fit.profile)
        write_profile(root / "zero-latency.yaml", merge_profile(fit.profile, {"sensors": [{"latency_s": 0.0}] *
                                                                             len(cell.mounts)}))
        block = {"command": "posekit seam tune train0 ... train8 --with-truth --out truth.yaml",
                 "tuned_latency_ms": [{"value_ms": round(v.value * 1e3, 3),
                                       "std_ms": None if v.std is None else round(v.std * 1e3, 3)}
                                      for v in fit.values if v.key.endswith("latency_s")]}
        nine = {k: v for k, v in scen.items() if k in ("nominal", "encoder offset 0.05 deg joint 1",
                                                         "encoder offset 0.05 deg joint 2",
                                                         "force-sensor bias 300 N along x",
                                                         "force-sensor bias 300 N along z")}
        if cell.latency_s[0] > 0:
            nine["latency undeclared (profile says 0)"] = ({}, "zero-latency.yaml")
        _score(block, label, root, cell, held, nine)
        out[label] = block
    return out


def _score(block: dict, label: str, root: Path, cell, held: range, scen: dict) -> None:
    """Track the held-out episodes of each scenario ``{name: (episode keywords, profile file in root or None)}``
    and put their summary into ``block``."""
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.tracker import track_log
    from tests.seam import independent_cell as ic

    for name, (kw, prof) in scen.items():
        errs, spr, sts = [], [], []
        for s in held:
            ep = ic.episode(cell, s, **kw)
            d = ic.write_episode(root / f"{name}-{s}".replace(" ", "_"), cell, ep, declare_latency=False)
            r = track_log(read_episode_log(d, profile=None if prof is None else root / prof))
            errs.append(ic.seam_frame_errors(r.estimate, ep))
            spr.append(r.spread)
            sts.append(r.status)
        block[name] = {"command": f"posekit seam track EPISODE{'' if prof is None else ' --profile ' + prof} "
                                  f"--out DIR (held-out seeds {held.start}-{held.stop - 1})",
                       **_summary(errs, spr, sts)}
        print(f"  independent {label} {name}: {block[name]['coverage_2sigma']} tracking "
              f"{block[name]['tracking']} confident-wrong {block[name]['confident_wrong']} (worst episode "
              f"{block[name]['confident_wrong_worst_episode']})", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="the JSON file to write")
    ap.add_argument("--episodes", type=int, default=None, help="episodes per scenario (default 20 / 30)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "src"))
    t0 = time.time()
    n_own = args.episodes or 20
    n_ind = args.episodes or 30
    print("own simulator:", flush=True)
    own = own_simulator(n_own)
    print("independent cell:", flush=True)
    with tempfile.TemporaryDirectory(prefix="posekit-validation-") as tmp:
        ind = independent_cell(n_ind, Path(tmp))
    data = {"command": "python benchmarks/seam_validation.py --out benchmarks/data/seam_validation.json"
                       + (f" --episodes {args.episodes}" if args.episodes else ""),
            "python": platform.python_version(), "seconds": round(time.time() - t0, 1),
            "own_simulator": own, "independent_cell": ind}
    write_json(args.out, data)
    return 0


def write_json(path, data: dict) -> Path:
    """Write a study's ``data`` (with its ``seconds``) to the JSON file ``path`` (its folder made) and say so."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {out} ({data['seconds']} s)")
    return out


if __name__ == "__main__":
    sys.exit(main())
