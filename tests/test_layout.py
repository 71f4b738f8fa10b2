"""The package's structure: layers, no import circles, no private names across files,
modules of a few hundred lines, and the deprecated import paths still working."""

import ast
import importlib
import sys
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "jaxgrav"

LAYERS = {
    # bottom: no jaxgrav imports but each other
    "constants": 0, "_io": 0, "_linalg": 0, "_pytree": 0, "_validate": 0, "_fusion": 0,
    "lattice": 0, "interp": 0, "fill": 0,
    "executables": 0, "xla_options": 0, "rare_cond": 0,
    "geodesy": 0,
    "grid": 1, "grid_axes": 1, "grid_files": 1, "grid_values": 1, "grid_windows": 1,
    "prepared": 1, "tracks": 1,
    "track_files": 1, "track_units": 1, "track_times": 1, "time_steps": 1, "track_degrees": 1,
    "track_columns": 1,
    "plot": 1,
    "fields": 2, "sim": 2,
    "datasets": 3,
    "match": 4, "filters": 4, "dov": 4,
    "scenarios": 5, "navigate": 5,
    "montecarlo": 6,
    "cli": 7,
}
"""Layer of each top-level module or package: a file may import only its own layer or
lower ones (and, within one layer, only its own package)."""

SHIMS = {"jaxgrav/match/filters/__init__.py", "jaxgrav/sensitivity.py", "jaxgrav/__init__.py"}
"""The package face and the deprecation shims, which re-export from higher layers."""

SHIM_IMPORTS = {("jaxgrav/grid.py", "jaxgrav.fields.spectral")}
"""Deprecated methods that call the function that replaced them (imported at call time)."""

MAX_LINES = 420


def _files():
    return sorted(p for p in ROOT.rglob("*.py") if "__pycache__" not in p.parts)


def _module(path):
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path):
    """(module imported, names, line) of every ``jaxgrav`` import in a file."""
    tree = ast.parse(path.read_text())
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] == "jaxgrav":
                out.append((node.module, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name, [], node.lineno) for a in node.names
                    if a.name.split(".")[0] == "jaxgrav"]
    return out


def _top(module):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_every_top_level_module_has_a_layer():
    tops = {p.stem if p.parent == ROOT else p.relative_to(ROOT).parts[0] for p in _files()}
    tops -= {"__init__", "sensitivity", "__main__"}
    assert tops <= set(LAYERS), sorted(tops - set(LAYERS))


def test_no_import_runs_upward():
    bad = []
    for path in _files():
        rel = str(path.relative_to(ROOT.parent))
        if rel in SHIMS:
            continue
        here = _top(_module(path))
        for mod, names, line in _imports(path):
            if (rel, mod) in SHIM_IMPORTS:
                continue
            targets = [mod] if _top(mod) else [f"jaxgrav.{n}" for n in names]
            for target in targets:
                there = _top(target)
                if there is None or there not in LAYERS or there == here:
                    continue
                if (LAYERS[there] > LAYERS[here]
                        or (LAYERS[there] == LAYERS[here] and LAYERS[here] >= 2)):
                    bad.append(f"{rel}:{line} ({here}, layer {LAYERS[here]}) imports "
                               f"{target} ({there}, layer {LAYERS[there]})")
    assert not bad, "\n".join(bad)


def test_no_import_circle_between_files():
    mods = {_module(p): p for p in _files()}
    graph = {m: set() for m in mods}
    for m, path in mods.items():
        if str(path.relative_to(ROOT.parent)) in SHIMS:
            continue
        for mod, names, _ in _imports(path):
            for target in [mod, *(f"{mod}.{n}" for n in names)]:
                if target in mods and target != m and not mods[target].name == "__init__.py":
                    graph[m].add(target)
    # Tarjan's strongly connected components
    index, low, stack, on, sccs, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in graph:
        if v not in index:
            visit(v)
    assert not sccs, sccs


def test_no_private_name_imported_from_another_file():
    bad = []
    for path in _files():
        for mod, names, line in _imports(path):
            bad += [f"{path.relative_to(ROOT.parent)}:{line} imports {n} from {mod}"
                    for n in names if n.startswith("_") and not n.startswith("__")]
    assert not bad, "\n".join(bad)


def test_modules_stay_small():
    big = {str(p.relative_to(ROOT.parent)): n for p in _files()
           if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not big, big


@pytest.mark.parametrize("old, new", [
    ("jaxgrav.sensitivity", "jaxgrav.dov.sensitivity"),
    ("jaxgrav.match.filters", "jaxgrav.filters"),
])
def test_deprecated_module_paths_warn_and_give_the_same_objects(old, new):
    sys.modules.pop(old, None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        shim = importlib.import_module(old)
    assert any(issubclass(w.category, DeprecationWarning) and old in str(w.message)
               for w in caught)
    target = importlib.import_module(new)
    for name in target.__all__:
        if hasattr(shim, name):
            assert getattr(shim, name) is getattr(target, name), name
    assert set(target.__all__) <= set(shim.__all__)


def test_make_test_groups_cover_every_test_file_once():
    """``make test-long`` runs the long tier in groups (Makefile TEST_GROUPS): every test file
    must be in exactly one, or its long tests would silently not run."""
    project = ROOT.parent
    line = next(x for x in (project / "Makefile").read_text().splitlines()
                if x.startswith("TEST_GROUPS"))
    covered = []
    for group in line.split(":=", 1)[1].strip().split("|"):
        for item in group.split():
            paths = sorted(project.glob(item)) if "*" in item else [project / item]
            for p in paths:
                covered += sorted(p.rglob("test_*.py")) if p.is_dir() else [p]
    every = sorted((project / "tests").rglob("test_*.py"))
    assert sorted(covered) == every, set(every) ^ set(covered)
