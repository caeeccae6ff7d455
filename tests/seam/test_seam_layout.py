"""DESIGN.md's seam layout: the engine (and the model) import no front end and no CLI; every module under 500
lines of the ones this layout introduced."""

import ast
from pathlib import Path

import pytest

SEAM = Path(__file__).resolve().parents[2] / "src" / "posekit" / "seam"


def _imports(path: Path) -> set:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the package
                pkg = path.relative_to(SEAM.parents[1]).with_suffix("").parts[:-node.level]
                base = ".".join(pkg + ((base,) if base else ()))
            out.add(base)
    return out


@pytest.mark.parametrize("path", sorted((SEAM / "engine").glob("*.py")) + [SEAM / "model.py"],
                         ids=lambda p: p.name)
def test_engine_and_model_import_no_front_end(path):
    bad = {m for m in _imports(path) if m.startswith(("posekit.seam.frontend", "posekit.cli"))}
    assert not bad, f"{path.name} imports {sorted(bad)}"


def test_the_new_modules_are_under_500_lines():
    new = ["model.py", "engine/step.py", "engine/filter.py", "engine/ekf.py", "engine/_linear.py",
           "engine/spread_bound.py", "frontend/profile.py", "frontend/tune.py", "frontend/tune_fit.py",
           "frontend/tune_truth.py", "frontend/config.py", "frontend/config_cell.py", "frontend/config_legacy.py",
           "frontend/config_messages.py", "frontend/config_types.py", "frontend/logs.py", "frontend/logs_setup.py"]
    long = {n: len((SEAM / n).read_text(encoding="utf-8").splitlines()) for n in new}
    assert all(v < 500 for v in long.values()), long
