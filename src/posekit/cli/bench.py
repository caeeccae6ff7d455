"""``posekit bench NAME``: run a benchmark script of ``benchmarks/`` against its peer."""

import importlib.util
import json
from pathlib import Path

from ..errors import ConfigError
from ._flags import bounded_int, check_flags

__all__ = ["add_parser", "BENCHMARKS"]

BENCHMARKS = ("profiler", "ceiling", "seam", "robots", "localcal", "server", "startup")
#: Most samples of one benchmark (profiles, frames, filter steps or calls; each benchmark takes at
#: least its own minimum).
MAX_COUNT = 10_000
PLANNED = ()


def add_parser(sub):
    p = sub.add_parser("bench", help="time a system against the peer a user would otherwise pick")
    p.add_argument("name", choices=[*BENCHMARKS, *PLANNED, "all"], help="which benchmark")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.add_argument("--count", type=bounded_int(1, MAX_COUNT, "samples"), default=None,
                   help=f"number of samples, 1..{MAX_COUNT} (default: the benchmark's)")
    p.add_argument("--rows", type=bounded_int(100, 10_000_000, "rows"), default=None,
                   help="localcal only: poses per trajectory file, 100..1e7 (default 200,000; the issue's "
                        "size is 1000000)")
    p.set_defaults(func=run)


def _benchmarks_dir() -> Path:
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "benchmarks"
        if (cand / "profiler.py").is_file():
            return cand
    raise ConfigError("benchmarks/ not found: `posekit bench` runs from a source checkout "
                      "(pip install -e . in a clone of posekit)")


def _load(name: str):
    path = _benchmarks_dir() / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"posekit_bench_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run(args) -> int:
    if args.name in PLANNED:
        raise ConfigError(f"benchmark '{args.name}' does not exist yet: its system is not implemented; "
                          f"available: {', '.join(BENCHMARKS)}")
    check_flags(args)
    names = BENCHMARKS if args.name == "all" else (args.name,)
    for name in names:
        extra = {"rows": args.rows} if name == "localcal" and getattr(args, "rows", None) else {}
        results = _load(name).run(count=args.count, verbose=not args.json, **extra)
        if args.json:
            for row in results:
                print(json.dumps(row))
    return 0
