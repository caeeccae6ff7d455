"""Re-run the command in the header of each shipped seam profile and compare every value, 1σ, note and the
episodes' SHA-256 with the file (issue 26: "a test checks that re-running it reproduces the file").

Run from a source checkout (about 1 min for the default, 15 s per example profile, on 2 cores); the suite runs
the same comparison (tests/seam/test_seam_profile.py)::

    python benchmarks/seam_profile_reproduce.py [PROFILE.yaml ...]

Without arguments: the shipped ones, ``src/posekit/seam/profiles/default.yaml`` and the examples'
``examples/seam/*-profile.yaml``. Exit status 0 when every profile is reproduced, 1
otherwise (the differing keys are printed).
"""

import argparse
import contextlib
import io
import shlex
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _flat(d, prefix=""):
    """``{dotted key: leaf}`` of nested mappings and lists."""
    out = {}
    items = d.items() if isinstance(d, dict) else enumerate(d) if isinstance(d, list) else None
    if items is None:
        return {prefix: d}
    for k, v in items:
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def reproduce(path: Path) -> list[str]:
    """The keys of ``path`` that its header's command does not reproduce (empty: reproduced)."""
    from posekit.cli.main import main
    from posekit.seam.frontend.profile import load_profile, profile_data

    shipped = load_profile(path)
    argv = shlex.split(shipped.fitted.command)
    if argv[:3] != ["posekit", "seam", "tune"]:
        return [f"fitted.command: expected 'posekit seam tune ...', got {shipped.fitted.command!r}"]
    argv = argv[1:]
    with tempfile.TemporaryDirectory() as tmp, contextlib.chdir(ROOT):  # the command's paths are the checkout's
        argv[argv.index("--out") + 1] = str(Path(tmp) / "again.yaml")
        with contextlib.redirect_stdout(io.StringIO()):
            rc = main(argv)
        if rc != 0:
            return [f"the command exited {rc}"]
        again = profile_data(load_profile(Path(tmp) / "again.yaml"))
    want = profile_data(shipped)
    for d in (again, want):
        d["fitted"].pop("command")
    a, w = _flat(again), _flat(want)
    return [f"{k}: file {w.get(k)!r}, command {a.get(k)!r}" for k in sorted(set(a) | set(w)) if a.get(k) != w.get(k)]


def main(argv=None) -> int:
    from posekit.seam.frontend.profile import DEFAULT_PROFILE

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    shipped = [DEFAULT_PROFILE, *sorted((ROOT / "examples" / "seam").glob("*-profile.yaml"))]
    ap.add_argument("profiles", nargs="*", type=Path, default=shipped)
    args = ap.parse_args(argv)
    bad = 0
    for p in args.profiles:
        diff = reproduce(p)
        print(f"{p}: {'reproduced' if not diff else f'{len(diff)} value(s) differ'}")
        for line in diff:
            print(f"  {line}")
        bad += bool(diff)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "src"))
    sys.exit(main())
