"""The package's imports follow the pipeline (docs/architecture.md, issue 27): a lower stage never
imports a higher one, and no two modules import each other, directly or through others.

The source is read with ``ast``, nothing is imported: every ``import`` statement counts, at module
level and inside functions (a function-level import hides a circle from Python, not from this
test), ``if TYPE_CHECKING:`` blocks included; relative imports are resolved. ``from pkg import
name`` is an import of the module ``pkg.name`` when that is a module, else of ``pkg`` (a package's
``__init__``).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "agvdyn"

#: The stages in pipeline order (docs/architecture.md), each with the modules (and packages, their
#: submodules included) it holds; a module belongs to its longest matching name. Low shared pieces
#: without a stage of their own (file writing, lazy imports, compiled helpers, the time base, the
#: segment vocabulary) sit with the platform; the row rules (filter and stiction guards, which the
#: planner shares with the identification) with the kinematics, as docs/architecture.md lists them.
STAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("platform", ("agvdyn", "agvdyn.platform", "agvdyn.segments_vocabulary", "agvdyn.time_base", "agvdyn._files",
                  "agvdyn._lazy", "agvdyn._memory", "agvdyn._numba_cache", "agvdyn._trig", "agvdyn._zero_phase",
                  "agvdyn._filter_cache", "agvdyn._ffbuild", "agvdyn._jit")),
    ("kinematics", ("agvdyn.kinematics", "agvdyn.odometry", "agvdyn.row_rules")),
    ("dynamics", ("agvdyn.dynamics", "agvdyn.dynamics_extended", "agvdyn.identifiability", "agvdyn.determinacy",
                  "agvdyn.ffcpp")),
    ("trajectories", ("agvdyn.trajectories",)),
    ("simulation", ("agvdyn.simulation", "agvdyn.export")),
    ("io", ("agvdyn.io",)),
    ("signals", ("agvdyn.signals",)),
    ("identification", ("agvdyn.identification", "agvdyn.preflight", "agvdyn.batch", "agvdyn.montecarlo",
                        "agvdyn.plan_check")),
    ("online", ("agvdyn.online",)),  # payload tracking: above identification (its row rules), issue 31
    ("validation", ("agvdyn.validation",)),
    ("report", ("agvdyn.report", "agvdyn.plots", "agvdyn.figure_data", "agvdyn.demo")),
    ("cli", ("agvdyn.cli", "agvdyn._aot_build")),  # the CLI may import anything
)

#: Imports allowed against the rules, each with its reason: (importer, imported) -> reason.
UPWARD_EXCEPTIONS: dict[tuple[str, str], str] = {
    ("agvdyn.simulation", "agvdyn.io"):
        "SimulationResult.write (simulation/result.py) saves the simulated log in the log schema (agvdyn.io.write_log, imported in "
        "the method); io never imports the simulation",
}
CIRCLE_EXCEPTIONS: dict[frozenset[str], str] = {}


def _module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its source."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]

    def known(target: str) -> str | None:
        parts = target.split(".")
        while parts and ".".join(parts) not in modules:
            parts.pop()
        return ".".join(parts) or None

    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        for target in targets:
            if target == "agvdyn" or target.startswith("agvdyn."):
                module = known(target)
                if module is not None and module != name:
                    out.add(module)
    return out


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def _stage(module: str) -> int | None:
    best: tuple[int, int] | None = None
    for index, (_, prefixes) in enumerate(STAGES):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > best[1]):
                best = (index, len(prefix))
    return None if best is None else best[0]


def _top(module: str, index: int) -> str:
    """The stage entry ``module`` falls under (``agvdyn.simulation`` for ``agvdyn.simulation.plant``)."""
    return max((p for p in STAGES[index][1] if module == p or module.startswith(p + ".")), key=len)


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in graph:
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
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return _graph()


def test_every_module_has_a_stage(graph):
    assert [m for m in graph if _stage(m) is None] == []


def test_no_upward_import(graph):
    upward = []
    for module, imported in graph.items():
        own = _stage(module)
        if STAGES[own][0] == "cli":
            continue
        for other in sorted(imported):
            theirs = _stage(other)
            if theirs > own and (_top(module, own), _top(other, theirs)) not in UPWARD_EXCEPTIONS:
                upward.append(f"{module} ({STAGES[own][0]}) imports {other} ({STAGES[theirs][0]})")
    assert upward == []


def test_no_import_circle(graph):
    circles = [c for c in _circles(graph) if frozenset(c) not in CIRCLE_EXCEPTIONS]
    assert circles == []


def test_the_exceptions_are_still_needed(graph):
    """An exception that no longer happens is removed from the list."""
    used = {(_top(m, _stage(m)), _top(o, _stage(o))) for m, imported in graph.items() for o in imported
            if _stage(o) > _stage(m)}
    assert [pair for pair in UPWARD_EXCEPTIONS if pair not in used] == []
    circles = {frozenset(c) for c in _circles(graph)}
    assert [sorted(c) for c in CIRCLE_EXCEPTIONS if c not in circles] == []


def test_the_scan_sees_function_level_and_relative_imports(tmp_path):
    package = tmp_path / "agvdyn"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "sub" / "__init__.py").write_text("")
    (package / "sub" / "a.py").write_text("def f():\n    from agvdyn.sub import b\n")
    (package / "sub" / "b.py").write_text("from . import a\nfrom .. import c\n")
    (package / "c.py").write_text("")
    modules = {_module_name(p, package): p for p in package.rglob("*.py")}
    seen = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert seen["agvdyn.sub.a"] == {"agvdyn.sub.b"}
    assert seen["agvdyn.sub.b"] == {"agvdyn.sub.a", "agvdyn.c"}
    assert _circles(seen) == [["agvdyn.sub.a", "agvdyn.sub.b"]]

