"""The import graph of the packages, against the layers of docs/architecture (top to bottom).

Reads every module of ``furnace_twin``, ``benchmarks``, ``backend`` and ``twin`` with ``ast`` (nothing is
imported or run), counts the imports between the layers' packages, and lists every import that runs
upward (a module importing one of a higher layer) or sideways (between two packages of one layer),
with file and line.  Imports inside functions count: a lazy import is still a dependency.

    python scripts/layers.py            # the package graph and the upward imports; exit 1 if any
    python scripts/layers.py --modules  # also every module-to-module cycle

``tests/test_layers.py`` runs it on the repository: no upward import, no cycle.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("furnace_twin", "benchmarks", "backend", "twin")

#: entries that are one module, not a package's prefix: ``twin`` is the public API (twin/__init__.py); a module
#: of twin that no entry names has no layer (tests/test_layers.py says which) instead of taking the API's
EXACT = {"twin"}
#: top to bottom; a module may import its own package and any package of a lower layer
LAYERS: tuple[tuple[str, ...], ...] = (
    ("furnace_twin",),  # the command line: composes all below
    ("benchmarks",),  # measures the server and the numerics
    ("backend.server",),  # `furnace-twin serve`
    ("backend.app",),  # the app factory
    ("backend.api",),  # routes, deps, schemas
    ("backend.viser",),  # the 3D view (follows runs through the run manager)
    ("backend.runs", "backend.studies"),  # hosting runs and studies
    ("backend.storage",),  # database, run folders, recordings
    ("backend.streaming",),  # frames, fan-out, series, rerun viewer
    ("backend.core",),  # settings, security, errors
    ("twin",),  # the public API (twin/__init__.py): the names a script uses, imported on first use
    ("twin.experiments",),  # what a user runs: a run, the campaign (its runs on the study engine's cluster)
    ("twin.studies",),  # design studies on Dask
    ("twin.runs",),  # the loop, its record, metrics
    ("twin.estimation", "twin.control"),  # the twin side
    ("twin.furnace",),  # the furnace side
    ("twin.model", "twin.radiation"),
    ("twin.physics",),
    ("twin.user_files",),
    ("twin.scenario",),
    ("twin.limits",),
    ("twin.config", "twin.events", "twin.endpoints", "twin.numerics", "twin.jsonable"),
    ("twin.event_words",),  # the words of the events (twin.events renders them; they import nothing of twin)
)


@dataclass(frozen=True)
class Import:
    module: str  # the importing module
    target: str  # the imported module (as written: a module, or a package)
    path: str  # the importing file, relative to the repository
    line: int


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> list[Import]:
    """Every import of one of :data:`PACKAGES` in the file (top level, in functions, under TYPE_CHECKING)."""
    name = module_name(path)
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from pkg import mod` names a module when pkg is a package of ours: count pkg.mod if it exists
            targets = [f"{node.module}.{a.name}" if _is_module(f"{node.module}.{a.name}") else node.module
                       for a in node.names]
        else:
            continue
        for t in dict.fromkeys(targets):  # one per statement and module
            if t.split(".")[0] in PACKAGES:
                found.append(Import(name, t, str(path.relative_to(ROOT)), node.lineno))
    return found


def _is_module(dotted: str) -> bool:
    base = ROOT.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def package_of(module: str) -> str:
    """The layer package a module belongs to: the longest entry of :data:`LAYERS` that prefixes it."""
    best = ""
    for layer in LAYERS:
        for pkg in layer:
            below = module.startswith(pkg + ".") and pkg not in EXACT
            if (module == pkg or below) and len(pkg) > len(best):
                best = pkg
    return best


def rank(pkg: str) -> int:
    """0 for the top layer; larger is lower."""
    return next(i for i, layer in enumerate(LAYERS) if pkg in layer)


def all_imports() -> list[Import]:
    out: list[Import] = []
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            out.extend(imports_of(path))
    return out


def wrong_way(imports: list[Import]) -> list[tuple[Import, str]]:
    """Imports that run upward or sideways between the layers, each with a word of why."""
    bad = []
    for imp in imports:
        src, dst = package_of(imp.module), package_of(imp.target)
        if src == dst or not src or not dst:
            continue
        if rank(dst) < rank(src):
            bad.append((imp, f"upward: {src} -> {dst}"))
        elif rank(dst) == rank(src):
            bad.append((imp, f"sideways: {src} -> {dst}"))
    return bad


def module_cycles(imports: list[Import]) -> list[list[str]]:
    """Strongly connected groups of modules (Tarjan) of more than one module: modules that import each other."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.target != imp.module and _is_module(imp.target):
            graph.setdefault(imp.module, set()).add(imp.target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    sys.setrecursionlimit(10_000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return groups


def package_edges(imports: list[Import]) -> Counter[tuple[str, str]]:
    return Counter((package_of(i.module), package_of(i.target)) for i in imports
                   if package_of(i.module) != package_of(i.target))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--modules", action="store_true", help="also list the module-to-module cycles")
    args = p.parse_args(argv)
    imports = all_imports()
    print("imports between packages (count), top layer first:")  # noqa: T201
    for (src, dst), n in sorted(package_edges(imports).items(), key=lambda e: (rank(e[0][0]), e[0])):
        print(f"  {src:20s} -> {dst:20s} {n:4d}")  # noqa: T201
    bad = wrong_way(imports)
    print(f"\nimports against the layers: {len(bad)}")  # noqa: T201
    for imp, why in bad:
        print(f"  {imp.path}:{imp.line}  {imp.module} -> {imp.target}  ({why})")  # noqa: T201
    cycles = module_cycles(imports)
    print(f"\nmodule cycles: {len(cycles)}")  # noqa: T201
    if args.modules:
        for group in cycles:
            print("  " + " <-> ".join(group))  # noqa: T201
    return 1 if bad or cycles else 0


if __name__ == "__main__":
    raise SystemExit(main())
