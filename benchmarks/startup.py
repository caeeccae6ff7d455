"""Benchmark behind ``posekit bench startup``: how long a command takes to start.

Wall time of whole processes, as a user types them, beside the peer every Python tool pays
first, ``python -c "import numpy"``:

1. ``posekit --help`` (target <= 0.3 s);
2. ``posekit profiler estimate ONE.csv --gauge demo-5`` on one profile with warm caches (the
   compiled kernels already on disk; one untimed run first makes sure), target <= 1.5 s;
3. ``python -c "import posekit.SYSTEM"`` for each system package.

Each figure is the median of ``count`` runs (default 7) of a fresh interpreter: its wall time
and its CPU time (user + system of the child process, which a loaded machine inflates much less
than the wall time; on an idle machine the two are close, start-up runs on one core). The
machines are shared and noisy, so compare with the peer of the same run; the load average
before and after is printed and kept in every row. With ``verbose`` the slowest imports of the
estimate (``python -X importtime``, cumulative) follow the table, then where the estimate's time
goes, step by step in one process (:data:`_STAGES`: NumPy, numba, the ``scipy.linalg`` numba
imports to check for BLAS, posekit, numba's registries, the gauge, the estimate).
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

try:
    import resource
except ImportError:                  # Windows: no CPU time of child processes, no load average
    resource = None

RUNS = 7
TARGETS_MS = {"startup.help": 300.0, "startup.estimate_one": 1500.0}
PEER = 'python -c "import numpy"'
SYSTEMS = ("profiler", "ceiling", "localcal", "seam")


def _children_cpu_s() -> float:
    if resource is None:
        return float("nan")
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _load() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def _times_ms(cmd, runs: int) -> tuple[float, float]:
    """Median wall and CPU (user + system) time of ``cmd`` over ``runs`` fresh processes, ms
    (a failure stops the bench)."""
    wall, cpu = [], []
    for _ in range(runs):
        c0 = _children_cpu_s()
        t0 = time.perf_counter()
        out = subprocess.run(cmd, capture_output=True, text=True)
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((_children_cpu_s() - c0) * 1e3)
        if out.returncode not in (0, 1):
            from posekit.errors import ConfigError
            raise ConfigError(f"bench startup: '{' '.join(cmd[-4:])}' failed: {out.stderr.strip()[-200:]}")
    return statistics.median(wall), statistics.median(cpu)


def _one_profile(folder: Path) -> Path:
    """A one-profile CSV (header x,z) of the bundled demo-5 gauge, simulated by posekit."""
    from posekit.profiler import NoiseModel, bundled_gauge, render_profiles, sample_poses

    gauge = bundled_gauge("demo-5")
    rng = np.random.default_rng(0)
    profile = render_profiles(gauge, sample_poses(gauge, 1, rng), NoiseModel(), rng)[0]
    path = folder / "one.csv"
    np.savetxt(path, profile, delimiter=",", header="x,z", comments="")
    return path


#: One fresh process that does what a one-profile estimate does, step by step, and prints each
#: step's CPU and wall seconds as JSON (``posekit bench startup``'s "where the time goes").
_STAGES = """
import io, json, sys, time
marks = [("", time.perf_counter(), time.process_time())]
def mark(name):
    marks.append((name, time.perf_counter(), time.process_time()))
import numpy; mark("import numpy")
import numba; mark("import numba")
import scipy.linalg; mark("import scipy.linalg (numba's BLAS check)")
import posekit._jit, posekit.profiler, posekit.profiler.stream.files; mark("import posekit.profiler")
from numba.core.registry import cpu_target
cpu_target.target_context.refresh(); mark("numba's registries")
from posekit.profiler.gauge.model import resolve_gauge
resolve_gauge("demo-5"); mark("load the gauge (3 cached kernels)")
from posekit.profiler.stream.files import estimate_file
estimate_file(sys.argv[1], "demo-5", stream=io.StringIO()); mark("estimate_file (7 cached kernels)")
estimate_file(sys.argv[1], "demo-5", stream=io.StringIO()); mark("estimate_file again")
print(json.dumps([(b[0], b[2] - a[2], b[1] - a[1]) for a, b in zip(marks, marks[1:])]))
"""


def _stages(py, one: Path) -> list[tuple[str, float, float]]:
    """(step, CPU s, wall s) of :data:`_STAGES` in a fresh process."""
    out = subprocess.run([py, "-c", _STAGES, str(one)], capture_output=True, text=True)
    return [tuple(r) for r in json.loads(out.stdout)] if out.returncode == 0 else []


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
        load_before = _load()
        peer_ms, peer_cpu_ms = _times_ms([py, "-c", "import numpy"], runs)
        cases = [("startup.help", "posekit --help", [py, "-m", "posekit", "--help"]),
                 ("startup.estimate_one", "posekit profiler estimate (one profile)", estimate)]
        cases += [(f"startup.import_{s}", f"import posekit.{s}", [py, "-c", f"import posekit.{s}"]) for s in SYSTEMS]
        rows = []
        for name, what, cmd in cases:
            ours, ours_cpu = _times_ms(cmd, runs)
            target = TARGETS_MS.get(name)
            rows.append({"name": name, "command": what, "ours_ms": ours, "ours_cpu_ms": ours_cpu, "baseline": PEER,
                         "baseline_ms": peer_ms, "baseline_cpu_ms": peer_cpu_ms, "speedup": peer_ms / ours,
                         "realtime_factor": None, "runs": runs, "target_ms": target,
                         "target_met": None if target is None else bool(ours <= target)})
        load = (load_before, _load())
        for r in rows:
            r["load_avg"] = list(load)
        slowest = _slowest_imports(estimate) if verbose else []
        stages = _stages(py, one) if verbose else []
    if verbose:
        print(f"posekit bench startup: a fresh process, median of {runs} runs, beside {PEER} "
              f"(load average {load[0]:.1f} -> {load[1]:.1f} on {os.cpu_count()} cores)")
        print(f"{'command':<44}{'wall':>9}{'cpu':>9}{'peer wall':>11}{'peer cpu':>10}{'ratio':>7}  target (wall)")
        for r in rows:
            target = "" if r["target_ms"] is None else (
                f"<= {r['target_ms'] / 1e3:g} s {'met' if r['target_met'] else 'NOT met'}")
            print(f"{r['command']:<44}{r['ours_ms'] / 1e3:>8.3f}s{r['ours_cpu_ms'] / 1e3:>8.3f}s"
                  f"{r['baseline_ms'] / 1e3:>10.3f}s{r['baseline_cpu_ms'] / 1e3:>9.3f}s"
                  f"{r['ours_ms'] / r['baseline_ms']:>7.2f}  {target}")
        print("slowest imports of the one-profile estimate (python -X importtime, cumulative): "
              + ", ".join(f"{m} {ms / 1e3:.2f} s" for m, ms in slowest))
        print("where a one-profile estimate's time goes (one process, step by step, CPU / wall): "
              + ", ".join(f"{name} {cpu:.3f} / {wall:.3f} s" for name, cpu, wall in stages))
        if os.environ.get("PYTHONDONTWRITEBYTECODE"):
            print("note: PYTHONDONTWRITEBYTECODE is set: every process compiles posekit's byte code again "
                  "(0.1-0.2 s more than an installed package takes)")
    return rows
