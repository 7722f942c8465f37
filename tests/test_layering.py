"""The architecture's rules, checked on the source (DESIGN.md, Layout): dependencies point one way,
app -> widgets -> model -> solvers; model and solvers never load Qt or VTK; no import cycle anywhere,
counting imports inside functions too (a lazy import is still a dependency)."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "widgets", "model", "solvers", "resources")
LAYER = {"solvers": 0, "model": 1, "resources": 1, "widgets": 2, "app": 3}
GUI_LIBRARIES = ("PySide6", "vtk", "vtkmodules", "pyvista", "pyvistaqt")


def _module_name(path: Path) -> str:
    return ".".join(path.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")


def import_graph() -> dict[str, set[str]]:
    """module -> the project modules it imports anywhere in its source (module level or in functions)."""
    modules = {_module_name(p): p for pkg in PACKAGES for p in (REPO / pkg).glob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                deps.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                for a in node.names:
                    full = f"{base}.{a.name}"
                    deps.add(full if full in modules else base)
        graph[name] = {d for d in deps if d in modules and d != name}
    return graph


def external_imports(package: str) -> set[str]:
    out: set[str] = set()
    for path in (REPO / package).glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                out.update(a.name.split(".")[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                out.add(node.module.split(".")[0])
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    """The check above could pass vacuously; a made-up graph with a lazy back-edge must be caught."""
    graph = {"app.cli": {"app.cli_solve"}, "app.cli_solve": {"app.cli"}, "model.rig": set()}
    assert cycles(graph) == [["app.cli", "app.cli_solve"]]


def test_dependencies_point_one_way():
    wrong = [f"{m} imports {d}" for m, deps in import_graph().items() for d in deps
             if LAYER[d.split(".")[0]] > LAYER[m.split(".")[0]]
             or (m.startswith("solvers") and not d.startswith("solvers"))]
    assert wrong == []


def test_model_and_solvers_are_free_of_qt_and_vtk():
    for package in ("model", "solvers"):
        assert external_imports(package).isdisjoint(GUI_LIBRARIES), package
    # and at run time: importing every model and solver module loads no GUI library
    names = sorted(m for m in import_graph() if m.split(".")[0] in ("model", "solvers"))
    code = ("import importlib, sys\n"
            f"for n in {names!r}: importlib.import_module(n)\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {GUI_LIBRARIES!r}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
