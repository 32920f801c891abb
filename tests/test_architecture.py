"""The house stays as the README's architecture section draws it: imports run one way.

Every ``import`` of the project's own modules is read from the source with :mod:`ast`, those
inside functions included (they are how an upward dependency hides), and checked against the
layers: geometry -> fem -> reduced -> bearingshaft across packages; inside ``reduced`` a model
never imports a solver; inside ``bearingshaft`` the scene schema at the bottom, shared helpers
above it, the stages above those, then the registry, the pipeline and budget, the sweep and
the command line. No two modules may import each other through any chain (no cycle), a stage
takes nothing from another stage, and the modules that write files or draw figures run no
solver. Long functions say why in their docstring.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections.abc import MutableMapping
from importlib import import_module
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("geometry", "fem", "reduced", "bearingshaft")

# bearingshaft's own floors, bottom up (a module imports only from its floor and below)
APP_FLOORS = (
    ("bearingshaft", "bearingshaft.scenes"),
    ("bearingshaft.digits", "bearingshaft.fanout", "bearingshaft.progress", "bearingshaft.output",
     "bearingshaft.estimates", "bearingshaft.systems", "bearingshaft.plots", "bearingshaft.render",
     "bearingshaft.correlate", "bearingshaft.gap_modes", "bearingshaft.envelopes", "bearingshaft.measures",
     "bearingshaft.measured", "bearingshaft.reproduction"),
    ("bearingshaft.stages",),
    ("bearingshaft.registry",),
    ("bearingshaft.budget", "bearingshaft.pipeline"),
    ("bearingshaft.sweep", "bearingshaft.jobs", "bearingshaft.identify"),
    ("bearingshaft.cli", "bearingshaft.__main__"),
)
SOLVERS = ("reduced.transient.integrate", "reduced.transient.exact", "reduced.transient.explicit",
           "reduced.transient.dop853", "reduced.transient.flow", "reduced.periodic", "reduced.studies",
           "fem.modal", "fem.analysis")
MAX_FUNCTION_LINES = 100
LENGTH_REASON = "Long because"  # a function over MAX_FUNCTION_LINES says why in its docstring


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _sources() -> dict[str, Path]:
    return {_module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


MODULES = _sources()


def _resolve(name: str) -> str | None:
    """The project module an imported name lives in (a module, or the package holding the name)."""
    while name:
        if name in MODULES:
            return name
        name = name.rpartition(".")[0]
    return None


def _imports(mod: str, path: Path) -> set[str]:
    """Project modules ``mod`` imports anywhere in its source (function bodies included)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            names = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for n in names:
            target = _resolve(n)
            if target is not None and target != mod:
                out.add(target)
    return out


class _ImportGraph(MutableMapping):
    """``{module: project modules it imports}``, read from the sources on first use rather than at collection:
    under pytest-xdist every worker collects every file, and the worker that does not run this one would parse
    the four packages for nothing (issue 28). A mutable mapping, so a test can plant edges with monkeypatch."""

    def __init__(self):
        self._edges = None

    @property
    def edges(self) -> dict[str, set[str]]:
        if self._edges is None:
            self._edges = {m: _imports(m, p) for m, p in MODULES.items()}
        return self._edges

    def __getitem__(self, key):
        return self.edges[key]

    def __setitem__(self, key, value):
        self.edges[key] = value

    def __delitem__(self, key):
        del self.edges[key]

    def __iter__(self):
        return iter(self.edges)

    def __len__(self):
        return len(self.edges)


GRAPH = _ImportGraph()


def _package_layer(mod: str) -> int:
    return PACKAGES.index(mod.split(".")[0])


def _app_floor(mod: str) -> int:
    best, floor = -1, -1
    for i, names in enumerate(APP_FLOORS):
        for n in names:
            if (mod == n or mod.startswith(n + ".")) and len(n) > best:
                best, floor = len(n), i
    return floor


def test_the_sources_are_read():
    # a guard on the reader itself: known edges must be seen, or every other test here passes vacuously
    assert len(MODULES) > 80
    assert "bearingshaft.registry" in GRAPH["bearingshaft.pipeline"]
    assert "reduced.models.gaps" in GRAPH["reduced.transient.exact"]


def test_no_package_imports_a_later_one():
    up = [(m, t) for m, ts in GRAPH.items() for t in ts if _package_layer(t) > _package_layer(m)]
    assert not up, "upward imports (geometry -> fem -> reduced -> bearingshaft): " + str(up)


def test_a_model_never_imports_a_solver():
    bad = [(m, t) for m, ts in GRAPH.items() if m.startswith("reduced.models")
           for t in ts if t.startswith(("reduced.transient", "reduced.periodic", "reduced.studies"))]
    assert not bad, bad


def test_every_application_module_has_a_floor():
    missing = [m for m in MODULES if m.startswith("bearingshaft") and _app_floor(m) < 0]
    assert not missing, f"modules not placed in APP_FLOORS (say where they belong): {missing}"


def test_the_application_imports_only_downward():
    up = [(m, t) for m, ts in GRAPH.items() if m.startswith("bearingshaft")
          for t in ts if t.startswith("bearingshaft") and _app_floor(t) > _app_floor(m)]
    assert not up, "upward imports inside bearingshaft (see APP_FLOORS): " + str(up)


def _stage_of(mod: str) -> str | None:
    """``bearingshaft.stages.X`` and ``bearingshaft.stages.X_part`` belong to stage X."""
    if not mod.startswith("bearingshaft.stages."):
        return None
    return mod.split(".")[2].split("_")[0]


def test_a_stage_takes_nothing_from_another_stage():
    bad = [(m, t) for m, ts in GRAPH.items() if _stage_of(m)
           for t in ts if _stage_of(t) and _stage_of(t) != _stage_of(m)]
    assert not bad, "shared code belongs in a helper module named for it, not in another stage: " + str(bad)


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in GRAPH:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    assert not _cycles()


def test_the_cycle_finder_finds_a_cycle(monkeypatch):
    # the finder on a planted circle: a -> b -> c -> a
    monkeypatch.setitem(GRAPH, "x.a", {"x.b"})
    monkeypatch.setitem(GRAPH, "x.b", {"x.c"})
    monkeypatch.setitem(GRAPH, "x.c", {"x.a"})
    assert ["x.a", "x.b", "x.c"] in _cycles()


def _writers() -> list[str]:
    """Modules that turn results into files and figures."""
    return [m for m in MODULES if m in ("bearingshaft.plots", "bearingshaft.render")
            or m.endswith("_files") or m.endswith(".figures") or m.endswith(".report")]


def test_writers_and_figures_run_no_solver():
    writers = _writers()
    assert writers, "no writer module found: the naming rule of _writers() is out of date"
    bad = [(m, t) for m in writers for t in GRAPH[m] if t.startswith(SOLVERS)]
    assert not bad, bad


def test_long_functions_say_why():
    long = []
    for mod, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES and LENGTH_REASON not in (ast.get_docstring(node) or ""):
                    long.append(f"{mod}.{node.name} ({n} lines)")
    assert not long, f"split these at their seams, or say '{LENGTH_REASON} ...' in the docstring: {long}"


@pytest.mark.parametrize("mod", ["bearingshaft.scenes", "bearingshaft.registry"])
def test_the_schema_and_the_registry_do_not_import_dask(mod):
    # the scene schema is read by every command: it must not pull the cluster machinery in
    seen, todo = set(), [mod]
    while todo:
        m = todo.pop()
        for t in GRAPH.get(m, ()):
            if t not in seen:
                seen.add(t)
                todo.append(t)
    assert not any(t.startswith("bearingshaft.sweep") for t in seen)
    for t in seen | {mod}:
        text = MODULES[t].read_text(encoding="utf-8")
        assert "import dask" not in text and "from dask" not in text and "from distributed" not in text, t


def test_computing_never_loads_matplotlib():
    # a stage's compute (bearingshaft/stages/<name>.py and its parts but <name>_files.py) and the
    # registry, pipeline and budget run without drawing: matplotlib is loaded only by the writers
    compute = sorted(m for m in MODULES if m.startswith("bearingshaft.stages.") and not m.endswith("_files"))
    assert len(compute) >= 8
    code = ("import sys\n" + "".join(f"import {m}\n" for m in [*compute, "bearingshaft.registry",
                                                                     "bearingshaft.pipeline", "bearingshaft.budget"])
            + "print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "False", "a computing module imports matplotlib (directly or through a writer)"


def test_every_stage_is_written_by_a_files_module():
    # the registry writes a stage's files with bearingshaft.stages.<name>_files.write, imported when the files
    # are written (Stage.write): a stage whose writer module was renamed or lost fails here, not mid-run
    from bearingshaft.registry import STAGES

    for s in STAGES:
        files = f"bearingshaft.stages.{s.files or s.name + '_files'}"
        assert files in MODULES, f"{s.name}: no module {files}"
        tree = ast.parse(MODULES[files].read_text(encoding="utf-8"))
        assert any(isinstance(n, ast.FunctionDef) and n.name == "write" for n in tree.body), f"{files} has no write"
        assert not hasattr(import_module(s.compute.__module__), "write"), f"{s.name}: a second writer in its stage"
