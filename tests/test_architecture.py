"""The architecture of DESIGN.md "Layout", tested on the source tree (``ast``, nothing imported).

The import graph: a node per module of ``src/posekit`` (a package is its ``__init__``), an edge
for every ``import`` / ``from ... import`` statement that names another posekit module —
**module-level and function-local imports alike**: an import deferred into a function still
makes the module depend on the other at run time, and a circle closed by one is the same
circle (``profiler/estimate/io.py`` and ``reading.py`` imported each other that way). Imports
under ``if TYPE_CHECKING:`` are left out (they never run). ``from pkg import name`` is an edge to
``pkg.name`` when that is a module, to the package's ``__init__`` otherwise; importing a module
also imports its parent packages, which is not counted as an edge (it is an ``__init__``'s
job not to import what imports it).
"""

import ast
from functools import cache
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
SYSTEMS = ("profiler", "ceiling", "localcal", "seam")
CORE = ("geometry", "robots", "io", "sweep", "report", "verdict", "errors", "_extras")

#: The estimator (or tracker) packages of each system (DESIGN.md "Layout"): a simulator
#: (``<system>/sim``) never imports them, and they never import the system's ``sim`` or ``studies``.
ESTIMATORS = {"profiler": ("estimate",), "ceiling": ("detect", "track"), "localcal": ("registration", "methods"),
              "seam": ("engine",)}

#: Import circles that are being removed on other branches this round. Each entry is the set of
#: modules of one circle (a strongly connected component of the graph). The lead removes an
#: entry once the branch that breaks the circle is merged; an entry that no longer matches a
#: circle fails the test, so the list cannot outlive its circles.
ALLOWED_CIRCLES: set = set()

#: Simulator imports of an estimator package that are being removed on other branches;
#: (importer, imported). Empty: localcal's episode moved to its studies and its trajectory type
#: to its model (issue 29).
ALLOWED_SIM_IMPORTS: set[tuple[str, str]] = set()


def _module_name(path: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    return ".".join(parts[:-1] if is_package else parts), is_package


def _type_checking_nodes(tree) -> set:
    """The import statements under ``if TYPE_CHECKING:`` (never executed)."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


@cache
def import_graph() -> dict[str, set[str]]:
    """Module → the posekit modules it imports (module level and inside functions)."""
    files = {_module_name(p): p for p in SRC.rglob("*.py")}
    modules = {name for name, _ in files}
    graph = {}

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    for (name, is_package), path in files.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_nodes(tree)
        package = name.split(".") if is_package else name.split(".")[:-1]
        targets = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package[:len(package) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    targets.add(sub if sub in modules else base)
        graph[name] = {t for t in map(resolve, targets) if t is not None and t != name and t.startswith("posekit")}
    return graph


def circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.add(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(frozenset(component))
    return found


def test_the_circle_finder_finds_a_circle_closed_inside_a_function(tmp_path):
    """The detector itself: a two-module circle, one edge function-local, one module-level."""
    graph = {"posekit.a": {"posekit.b"}, "posekit.b": {"posekit.a", "posekit.c"}, "posekit.c": set(),
             "posekit.d": {"posekit.e"}, "posekit.e": {"posekit.f"}, "posekit.f": {"posekit.d"}}
    assert sorted(map(sorted, circles(graph))) == [["posekit.a", "posekit.b"], ["posekit.d", "posekit.e", "posekit.f"]]
    # and the graph sees both kinds of import (io.py <-> reading.py were both function-local)
    g = import_graph()
    assert "posekit.profiler.stream.files" in g["posekit.cli.profiler"]          # imported inside run_estimate
    assert "posekit.verdict" in g["posekit.profiler.estimate.result"]            # module level


def test_no_import_circle_in_src():
    found = set(circles(import_graph()))
    new = [sorted(c) for c in found - ALLOWED_CIRCLES]
    assert not new, f"import circles (break them: import each name from its real home): {new}"
    stale = [sorted(c) for c in ALLOWED_CIRCLES - found]
    assert not stale, f"these allowed circles are gone: remove them from ALLOWED_CIRCLES: {stale}"


def _system_modules(system: str, part: str) -> list[str]:
    prefix = f"posekit.{system}.{part}"
    return [m for m in import_graph() if m == prefix or m.startswith(prefix + ".")]


@pytest.mark.parametrize("system", SYSTEMS)
def test_simulators_never_import_the_estimator(system):
    """``<system>/sim`` may use the model, never the estimator (DESIGN.md "Layout")."""
    graph = import_graph()
    estimators = tuple(f"posekit.{system}.{e}" for e in ESTIMATORS[system])
    bad = sorted((m, t) for m in _system_modules(system, "sim") for t in graph[m]
                 if t.startswith(estimators) and (m, t) not in ALLOWED_SIM_IMPORTS)
    assert not bad, f"{system}: simulator modules import the estimator: {bad}"


@pytest.mark.parametrize("system", SYSTEMS)
def test_estimators_never_import_their_simulator_or_studies(system):
    graph = import_graph()
    forbidden = (f"posekit.{system}.sim", f"posekit.{system}.studies")
    bad = sorted((m, t) for e in ESTIMATORS[system] for m in _system_modules(system, e) for t in graph[m]
                 if t == forbidden[0] or t == forbidden[1] or t.startswith(tuple(f + "." for f in forbidden)))
    assert not bad, f"{system}: estimator modules import the simulator or the studies: {bad}"


@pytest.mark.parametrize("system", [s for s in SYSTEMS if (SRC / "posekit" / s / "model").is_dir()])
def test_the_model_imports_only_the_core(system):
    """``<system>/model`` is plain data: it imports the core and its own model, nothing else of
    the system (no estimator, simulator or studies)."""
    graph = import_graph()
    own = f"posekit.{system}.model"
    bad = sorted((m, t) for m in _system_modules(system, "model") for t in graph[m]
                 if t.startswith(f"posekit.{system}") and not (t == own or t.startswith(own + ".")))
    assert not bad, f"{system}: the model imports other parts of the system: {bad}"


def test_allowed_sim_imports_still_exist():
    graph = import_graph()
    stale = sorted(pair for pair in ALLOWED_SIM_IMPORTS if pair[0] in graph and pair[1] not in graph[pair[0]])
    gone = sorted(pair for pair in ALLOWED_SIM_IMPORTS if pair[0] not in graph)
    assert not stale + gone, f"remove from ALLOWED_SIM_IMPORTS: {stale + gone}"


def test_systems_import_only_the_core_and_nothing_imports_the_cli():
    graph = import_graph()
    bad = []
    for m, targets in graph.items():
        parts = m.split(".")
        for t in targets:
            tp = t.split(".")
            if len(parts) > 1 and parts[1] in SYSTEMS and len(tp) > 1 and tp[1] in SYSTEMS and tp[1] != parts[1]:
                bad.append((m, t))                                  # one system imports another
            if len(parts) > 1 and parts[1] in CORE and len(tp) > 1 and tp[1] in SYSTEMS + ("cli",):
                bad.append((m, t))                                  # the core imports a system or the CLI
            if tp[:2] == ["posekit", "cli"] and parts[:2] not in (["posekit", "cli"], ["posekit", "__main__"]):
                bad.append((m, t))                                  # only the CLI imports the CLI
    assert not bad, bad


# --------------------------------------------------------------------------- explicit APIs

#: ``__init__`` files that must list their public API explicitly: every system's package and
#: sub-package, the core's and the CLI's.
EXPLICIT = ["posekit", "posekit.cli", "posekit.geometry", "posekit.robots", "posekit.io"] + sorted(
    m for m in import_graph() if m.startswith(("posekit.profiler", "posekit.ceiling", "posekit.localcal",
                                               "posekit.seam"))
    and (SRC / Path(*m.split("."))).is_dir())


def _defines(module: str, name: str) -> bool:
    """Whether ``module`` defines ``name`` itself (def, class or assignment at its top level)."""
    path = SRC / Path(*module.split("."))
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)) and node.name == name:
            return True
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, (ast.AnnAssign, ast.AugAssign)) else []
        if any(isinstance(t, ast.Name) and t.id == name for t in targets):
            return True
    return False


@pytest.mark.parametrize("package", EXPLICIT)
def test_init_lists_its_api_imported_from_the_real_home(package):
    """``__all__`` is a literal list; no ``__getattr__``; every listed name is imported from the
    module that defines it (not from a module that re-exports it), defined in the ``__init__``, or
    one of the package's modules (a sub-package of a system lists its modules: its names are
    exported by the system's ``__init__``, and re-exporting them in the sub-package would close
    import circles at run time, e.g. gauge/ambiguity.py uses estimate/'s kernels)."""
    path = SRC / Path(*package.split(".")) / "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    assert ast.get_docstring(tree), f"{package}: the package docstring says what is in it"
    assert not any(isinstance(n, ast.FunctionDef) and n.name == "__getattr__" for n in tree.body), \
        f"{package}: lazy __getattr__ re-exports hide the API"
    all_nodes = [n for n in tree.body if isinstance(n, ast.Assign) and any(
        isinstance(t, ast.Name) and t.id == "__all__" for t in n.targets)]
    assert len(all_nodes) == 1, f"{package}: one literal __all__"
    names = ast.literal_eval(all_nodes[0].value)
    assert len(names) == len(set(names)), f"{package}: __all__ lists a name twice"
    origin = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            for alias in node.names:
                origin[alias.asname or alias.name] = (base, alias.name)
    here = SRC / Path(*package.split("."))
    for name in names:
        if (here / f"{name}.py").is_file() or (here / name / "__init__.py").is_file():
            assert name not in origin, f"{package}.{name}: a submodule listed in __all__ is not re-bound"
            continue                                    # a public submodule (``from pkg import *`` imports it)
        if name in origin:
            module, real = origin[name]
            assert _defines(module, real), f"{package}.{name}: imported from {module}, which does not define it"
        else:
            assert _defines(package, name), f"{package}.{name}: listed in __all__ but neither imported nor defined"


def test_every_module_holds_under_500_lines():
    """One concept per module (STYLE.md): a module that grows past 500 lines is split, not excused."""
    long = {str(p.relative_to(SRC)): n for p in sorted(SRC.rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) >= 500}
    assert long == {}
