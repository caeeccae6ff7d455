"""What a command imports before it does its work (issue 30: fast start; the timings are
``posekit bench startup``'s, never a test's).

Each check runs in a fresh interpreter and reads ``sys.modules``: a heavy library imported at
module level anywhere on the path of ``posekit --help`` or of a one-profile
``posekit profiler estimate`` puts its name there.
"""

import json
import subprocess
import sys

import pytest

#: Libraries a one-profile estimate never calls; importing them cost 0.1-1 s each
#: (``scipy.optimize`` through the closed-loop response fit took 1 s of a 2.6 s estimate).
HEAVY = ("scipy.optimize", "scipy.stats", "scipy.spatial", "scipy.special", "scipy.signal", "scipy.interpolate",
         "scipy.sparse", "matplotlib", "cv2", "pandas", "dask", "distributed", "lxml", "statsmodels", "cvxpy",
         "tqdm", "PIL")

#: The modules ``posekit profiler estimate`` imports: the CLI, then inside ``run_estimate``.
ESTIMATE_IMPORTS = ("posekit.cli.main", "posekit.cli.profiler", "posekit.cli.profiler_replay", "posekit.profiler",
                    "posekit.profiler.gauge.check", "posekit.profiler.stream.files")


def _loaded(code: str) -> set[str]:
    """Names in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    code += "\nimport sys, json; print(json.dumps(sorted(sys.modules)), file=sys.stderr)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    return set(json.loads(out.stderr.strip().splitlines()[-1]))


def _heavy(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY))


@pytest.mark.parametrize("argv", [["--help"], ["profiler", "estimate", "--help"]])
def test_help_imports_no_numpy(argv):
    loaded = _loaded(f"from posekit.cli.main import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass")
    assert "posekit.cli.main" in loaded                    # the code ran
    assert not {"numpy", "numba", "yaml", "scipy"} & loaded, sorted({"numpy", "numba", "yaml", "scipy"} & loaded)


def test_estimate_path_imports_no_heavy_library():
    loaded = _loaded("\n".join(f"import {m}" for m in ESTIMATE_IMPORTS))
    assert {"posekit.profiler.loop.response", "posekit.profiler.studies.study_limits", "numba"} <= loaded
    assert _heavy(loaded) == []


def test_the_check_sees_a_heavy_import():
    # the same check on a module that does need scipy.optimize at import: it must be seen
    assert "scipy.optimize" in _heavy(_loaded("import scipy.optimize"))
