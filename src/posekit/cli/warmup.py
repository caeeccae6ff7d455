"""``posekit warmup [SYSTEM ...]``: compile the numba kernels ahead of their first use.

What a user runs once after installing (or upgrading) posekit, and what a cell's start-up
script calls: every system's kernels are compiled into the cache (see :mod:`posekit._jit`),
so the first real command starts at once. The kernels compile for the argument types a
command passes them, so each warm-up task is a small run of the commands themselves
(tiny sizes, into a temporary folder); the tasks run in parallel processes, one per core.
"""

import json
import os
import subprocess
import sys
import tempfile
import time

from ..errors import ConfigError
from ._flags import bounded_int, check_flags

__all__ = ["add_parser", "run", "TASKS", "SYSTEMS"]

#: The warm-up tasks: ``(name, system, commands)``, each command a ``posekit`` argument list
#: (``{tmp}`` is the task's temporary folder), run in order in one process. Together they call
#: every kernel a command calls, with the argument types the commands pass; tasks share as
#: few kernels as they can (two processes compiling one kernel do the work twice) and come
#: longest first, so that the processes finish together.
TASKS = (
    ("profiler-estimate", "profiler", (
        ["profiler", "simulate", "--gauge", "demo-5", "--count", "3", "--seed", "1", "--out", "{tmp}/sim"],
        ["profiler", "estimate", "{tmp}/sim/profiles.npz", "--gauge", "demo-5", "--out", "{tmp}/mle.jsonl"],
        ["profiler", "estimate", "{tmp}/sim/profiles.npz", "--gauge", "demo-5", "--method", "cf",
         "--out", "{tmp}/cf.csv"],
        ["demo", "--runs", "1", "--axes", "x", "--steps-mm", "1", "--no-camera", "--out", "{tmp}/demo"],
        ["profiler", "simulate", "--gauge", "demo-5", "--count", "60", "--seed", "2", "--out", "{tmp}/cal"],
        ["profiler", "calibrate-gauge", "{tmp}/cal/profiles.npz", "--gauge", "demo-5", "--out", "{tmp}/asbuilt.yaml"],
    )),
    ("seam", "seam", (
        ["seam", "demo", "--steps", "20", "--particles", "50"],
        ["seam", "simulate", "--sensors", "1", "--steps", "20", "--particles", "50", "--record-particles", "0",
         "--save-log", "{tmp}/log", "--out", "{tmp}/sim"],
        ["seam", "track", "{tmp}/log", "--out", "{tmp}/track"],
    )),
    ("profiler-realistic", "profiler", (
        ["profiler", "simulate", "--gauge", "demo-5", "--count", "3", "--realistic", "--out", "{tmp}/real"],
    )),
    ("ceiling", "ceiling", (
        ["ceiling", "demo", "--duration-s", "1", "--out", "{tmp}/ceiling"],
    )),
    ("localcal", "localcal", (
        ["localcal", "demo", "--camera-hz", "1", "--plot-hz", "0"],
    )),
)
SYSTEMS = ("profiler", "ceiling", "localcal", "seam")


def add_parser(sub):
    p = sub.add_parser("warmup", help="compile the numba kernels ahead of their first use (once after install)")
    p.add_argument("systems", nargs="*", metavar="SYSTEM", help=f"{', '.join(SYSTEMS)} (default: all)")
    p.add_argument("--workers", type=bounded_int(1, 64, "processes"), default=None,
                   help="tasks compiled at once, each in its own process, 1..64 (default: one per core)")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import _jit
    from ._common import progress

    check_flags(args)
    unknown = [s for s in args.systems if s not in SYSTEMS]
    if unknown:
        raise ConfigError(f"warmup: unknown system '{unknown[0][:40]}'; expected one of {', '.join(SYSTEMS)}")
    chosen = set(args.systems or SYSTEMS)
    tasks = [t for t in TASKS if t[1] in chosen]
    workers = args.workers or os.cpu_count() or 1
    print(f"posekit warmup: {len(tasks)} tasks ({', '.join(sorted(chosen))}) in {min(workers, len(tasks))} "
          f"processes; compiled kernels go to {_jit.cache_dir()}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    results = []
    for res in progress(_run_tasks(tasks, workers), total=len(tasks), desc="warmup", unit="task"):
        results.append(res)
        if not sys.stderr.isatty():
            print(f"posekit warmup: {_describe(res)}", file=sys.stderr, flush=True)
    wall = time.perf_counter() - t0
    compiled = sum(r.get("compiled", 0) for r in results)
    failed = [r for r in results if r.get("error")]
    skipped = [r for r in results if r.get("skipped")]
    print(f"posekit warmup: {compiled} kernels compiled in {wall:.0f} s ({len(results) - len(failed) - len(skipped)} "
          f"of {len(results)} tasks warm{f', {len(skipped)} skipped' if skipped else ''}); later commands load them")
    for r in sorted(results, key=lambda r: r["task"]):
        print(f"  {_describe(r)}")
    return 1 if failed else 0


def _describe(res: dict) -> str:
    if res.get("skipped"):
        return f"{res['task']}: skipped: {res['skipped']}"
    if res.get("error"):
        return f"{res['task']}: not warmed: {res['error']}"
    return f"{res['task']}: {res['compiled']} kernels compiled, {res['s']:.1f} s"


def _run_tasks(tasks, workers: int):
    """Yield each task's result as it finishes, at most ``workers`` processes at a time (an
    interrupted warm-up ends its processes)."""
    pending = list(tasks)
    running = []
    try:
        while pending or running:
            while pending and len(running) < workers:
                name = pending.pop(0)[0]
                cmd = [sys.executable, "-c", f"from posekit.cli._warmup_task import run_task; run_task({name!r})"]
                out, err = tempfile.TemporaryFile("w+"), tempfile.TemporaryFile("w+")   # no pipe to fill
                running.append((name, time.perf_counter(), subprocess.Popen(cmd, stdout=out, stderr=err), out, err))
            for item in list(running):
                name, t0, proc, out, err = item
                if proc.poll() is None:
                    continue
                running.remove(item)
                texts = []
                for f in (out, err):
                    f.seek(0)
                    texts.append(f.read())
                    f.close()
                yield _result(name, time.perf_counter() - t0, proc.returncode, *texts)
            time.sleep(0.05)
    finally:
        for _, _, proc, out, err in running:
            proc.kill()
            proc.wait()
            out.close()
            err.close()


def _result(name: str, seconds: float, code: int, out: str, err: str) -> dict:
    lines = out.strip().splitlines()
    try:
        res = json.loads(lines[-1])
    except (IndexError, ValueError):
        last = (err.strip().splitlines() or [f"exit {code}"])[-1]
        res = {"task": name, "compiled": 0, "error": last[:200]}
    res["s"] = seconds
    return res
