"""Benchmark behind ``posekit bench startup``: how long a command takes to start.

Wall time of whole processes, as a user types them, beside the peer every Python tool pays
first, ``python -c "import numpy"``:

1. ``posekit --help`` (target <= 0.3 s);
2. ``posekit profiler estimate ONE.csv --gauge demo-5`` on one profile with warm caches (the
   compiled kernels already on disk; one untimed run first makes sure), target <= 1.5 s;
3. ``python -c "import posekit.SYSTEM"`` for each system package.

Each figure is the median of ``count`` runs (default 7) of a fresh interpreter; the machines
are shared and noisy, so compare with the peer of the same run. With ``verbose`` the slowest
imports of the estimate (``python -X importtime``, cumulative) follow the table.
"""

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RUNS = 7
TARGETS_MS = {"startup.help": 300.0, "startup.estimate_one": 1500.0}
PEER = 'python -c "import numpy"'
SYSTEMS = ("profiler", "ceiling", "localcal", "seam")


def _wall_ms(cmd, runs: int) -> float:
    """Median wall time of ``cmd`` over ``runs`` fresh processes, ms (a failure stops the bench)."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = subprocess.run(cmd, capture_output=True, text=True)
        times.append((time.perf_counter() - t0) * 1e3)
        if out.returncode not in (0, 1):
            from posekit.errors import ConfigError
            raise ConfigError(f"bench startup: '{' '.join(cmd[-4:])}' failed: {out.stderr.strip()[-200:]}")
    return statistics.median(times)


def _one_profile(folder: Path) -> Path:
    """A one-profile CSV (header x,z) of the bundled demo-5 gauge, simulated by posekit."""
    from posekit.profiler import NoiseModel, bundled_gauge, render_profiles, sample_poses

    gauge = bundled_gauge("demo-5")
    rng = np.random.default_rng(0)
    profile = render_profiles(gauge, sample_poses(gauge, 1, rng), NoiseModel(), rng)[0]
    path = folder / "one.csv"
    np.savetxt(path, profile, delimiter=",", header="x,z", comments="")
    return path


def _slowest_imports(cmd, n: int = 6) -> list[tuple[str, float]]:
    """The ``n`` top-level imports with the largest cumulative time, ``python -X importtime``."""
    out = subprocess.run([cmd[0], "-X", "importtime", *cmd[1:]], capture_output=True, text=True)
    rows = []
    for line in out.stderr.splitlines():
        parts = line.split("|")
        if len(parts) == 3 and parts[1].strip().isdigit() and not parts[2].startswith("  "):
            rows.append((parts[2].strip(), int(parts[1]) / 1e3))
    return sorted(rows, key=lambda r: -r[1])[:n]


def run(count=None, verbose=True):
    """Run the benchmark; returns the JSON rows (``posekit bench`` contract)."""
    runs = max(int(count or RUNS), 3)
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="posekit-bench-startup-") as tmp:
        one = _one_profile(Path(tmp))
        estimate = [py, "-m", "posekit", "profiler", "estimate", str(one), "--gauge", "demo-5"]
        subprocess.run(estimate, capture_output=True)            # warm caches (compiles if they are cold)
        peer_ms = _wall_ms([py, "-c", "import numpy"], runs)
        cases = [("startup.help", "posekit --help", [py, "-m", "posekit", "--help"]),
                 ("startup.estimate_one", "posekit profiler estimate (one profile)", estimate)]
        cases += [(f"startup.import_{s}", f"import posekit.{s}", [py, "-c", f"import posekit.{s}"]) for s in SYSTEMS]
        rows = []
        for name, what, cmd in cases:
            ours = _wall_ms(cmd, runs)
            target = TARGETS_MS.get(name)
            rows.append({"name": name, "command": what, "ours_ms": ours, "baseline": PEER, "baseline_ms": peer_ms,
                         "speedup": peer_ms / ours, "realtime_factor": None, "runs": runs, "target_ms": target,
                         "target_met": None if target is None else bool(ours <= target)})
        slowest = _slowest_imports(estimate) if verbose else []
    if verbose:
        print(f"posekit bench startup: wall time of a fresh process, median of {runs} runs, beside {PEER}")
        print(f"{'command':<44}{'posekit':>10}{'peer':>10}{'ratio':>8}  target")
        for r in rows:
            target = "" if r["target_ms"] is None else (
                f"<= {r['target_ms'] / 1e3:g} s {'met' if r['target_met'] else 'NOT met'}")
            print(f"{r['command']:<44}{r['ours_ms'] / 1e3:>9.3f}s{r['baseline_ms'] / 1e3:>9.3f}s"
                  f"{r['ours_ms'] / r['baseline_ms']:>8.2f}  {target}")
        print("slowest imports of the one-profile estimate (python -X importtime, cumulative): "
              + ", ".join(f"{m} {ms / 1e3:.2f} s" for m, ms in slowest))
    return rows
