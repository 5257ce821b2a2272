#!/usr/bin/env python3
"""Layout check of the markerplace package: module sizes and import cycles.

Prints every module of ``src/markerplace`` over ``--max-lines`` lines (default 400) and every
import cycle between modules, found from the source with :mod:`ast` (nothing is imported):

* **top-level cycles**: modules that import each other when they are loaded (imports at module
  level, ``if TYPE_CHECKING:`` blocks left out). These can fail at import time depending on
  which module is loaded first;
* **cycles through deferred imports**: the same graph with the imports inside functions added.
  They load fine but still mean two modules depend on each other.

An edge goes to the module named in the import: ``from .x import y`` reaches ``x`` (or
``x/y.py`` when ``y`` is a submodule); importing ``a.b.c`` also runs the ``__init__`` of ``a``
and ``a.b``, which count as edges too.

* **cycles behind TYPE_CHECKING**: the same with the imports under ``if TYPE_CHECKING:`` added
  (a type annotation is a dependency too; shared types live in a types module instead);
* **package-level cycles**: at every level of the package tree, the graph between sibling
  packages and modules (:func:`package_graphs`), with every import counted;
* **imports inside functions**: only of the short list :data:`HEAVY_OPTIONAL`;
* **the planner apart from the testbed**: nothing a plan runs (:data:`PLANNER`: ``plan/``,
  ``pipelines/plan.py``, ``pipelines/plan_frames.py``) imports ``testbed/``, directly or through
  what it imports (:func:`planner_testbed_imports`); what both use lives in ``simulation/``;
* **module names**: one file name per meaning: no two modules share a file name
  (:func:`repeated_names`) except those of :data:`SHARED_NAMES`.

Exit status 1 when any of these is found or a module is over ``--fail-lines`` (when given),
0 otherwise. ``tests/test_layout.py`` runs the same functions with its allow-list.

Usage::

    python scripts/check_layout.py [--max-lines 400] [--fail-lines N] [--root src/markerplace]
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "markerplace"


def module_files(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of the package (``__init__`` = package)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def line_counts(root: Path = ROOT) -> dict[str, int]:
    """Dotted module name -> number of lines."""
    return {name: len(path.read_text(encoding="utf-8").splitlines()) for name, path in module_files(root).items()}


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.Module, type_checking: bool = False):
    """(node, deferred) for every import statement; deferred = inside a function. Imports under
    ``if TYPE_CHECKING:`` are left out unless ``type_checking`` (then they count as deferred)."""

    def walk(nodes, deferred):
        for node in nodes:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                yield node, deferred
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                yield from walk(ast.iter_child_nodes(node), True)
            elif isinstance(node, ast.If) and _is_type_checking(node.test):
                if type_checking:
                    yield from walk(node.body, True)
                yield from walk(node.orelse, deferred)
            else:
                yield from walk(ast.iter_child_nodes(node), deferred)

    yield from walk(tree.body, False)


def _with_parents(name: str, modules: dict[str, Path]) -> list[str]:
    """``a.b.c`` -> the known modules among ``a``, ``a.b``, ``a.b.c``."""
    parts = name.split(".")
    return [m for m in (".".join(parts[:i]) for i in range(1, len(parts) + 1)) if m in modules]


def import_graph(root: Path = ROOT, deferred: bool = False, type_checking: bool = False) -> dict[str, set[str]]:
    """Module -> modules of the package it imports (at module level; also inside functions
    when ``deferred``; also under ``if TYPE_CHECKING:`` when ``type_checking``). Self-edges of a
    package's ``__init__`` to its own parents are dropped."""
    modules = module_files(root)
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        is_pkg = path.name == "__init__.py"
        package = name if is_pkg else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node, inner in _imports(tree, type_checking):
            if inner and not deferred:
                continue
            targets: list[str] = []
            if isinstance(node, ast.Import):
                for alias in node.names:
                    targets += _with_parents(alias.name, modules)
            else:
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                targets += _with_parents(mod, modules)
                for alias in node.names:
                    sub = f"{mod}.{alias.name}"
                    if sub in modules:
                        targets.append(sub)
            for t in targets:
                # a module's own package __init__ runs before it: not an edge of this module
                if t != name and not name.startswith(t + "."):
                    graph[name].add(t)
    return graph


def package_graphs(graph: dict[str, set[str]]) -> dict[str, dict[str, set[str]]]:
    """Per package P: the graph between P's direct children (subpackages and modules). An import
    of a module in child A's subtree from child B's subtree is the edge B -> A; imports of P's
    own ``__init__`` and of anything outside P do not count at P's level. A cycle at any level
    is a package-level cycle (e.g. ``plan`` -> ``report`` -> ``plan`` at the top level)."""
    out: dict[str, dict[str, set[str]]] = {}
    for a, targets in graph.items():
        for b in targets:
            pa, pb = a.split("."), b.split(".")
            common = 0
            while common < min(len(pa), len(pb)) and pa[common] == pb[common]:
                common += 1
            if common == len(pa) or common == len(pb):
                continue  # one is the other's package (its __init__): not an edge between siblings
            parent = ".".join(pa[:common])
            level = out.setdefault(parent, {})
            ca, cb = ".".join(pa[:common + 1]), ".".join(pb[:common + 1])
            level.setdefault(ca, set()).add(cb)
            level.setdefault(cb, set())
    return out


def package_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Cycles between sibling packages/modules at every level of the package tree."""
    found = []
    for level in package_graphs(graph).values():
        found += cycles(level)
    return sorted(found, key=lambda c: (-len(c), c))


HEAVY_OPTIONAL = ("open3d", "moderngl", "dask", "distributed", "matplotlib", "reportlab", "skimage", "pupil_apriltags",
                  "trimesh", "scipy", "cv2", "PIL", "faiss", "numba", "gtsam", "msgpack", "psutil", "tqdm",
                  "ifcopenshell", "robotpy_apriltag")
"""Third-party modules that may be imported inside a function: heavy to load (a GL context,
OpenMP runtimes, a plotting stack, compiled kernels) or needed by few commands, so that
``markerplace --help`` and a one-line argument error stay fast. Everything else, and every
module of markerplace itself, is imported at module level."""


def deferred_imports(root: Path = ROOT) -> list[tuple[str, int, str]]:
    """(module, line, imported module) of every import inside a function that is not of a
    :data:`HEAVY_OPTIONAL` module."""
    out = []
    for name, path in module_files(root).items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node, inner in _imports(tree):
            if not inner:
                continue
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [
                ("." * node.level) + (node.module or "")]
            for mod in mods:
                if mod.split(".")[0] not in HEAVY_OPTIONAL:
                    out.append((name, node.lineno, mod))
    return sorted(out)


PLANNER = ("markerplace.plan", "markerplace.pipelines.plan", "markerplace.pipelines.plan_frames")
"""Modules (and packages, with everything in them) that a plan runs."""
TESTBED = "markerplace.testbed"
"""The evaluation package no planner module may reach."""


def planner_testbed_imports(root: Path = ROOT) -> list[list[str]]:
    """For every testbed module that a :data:`PLANNER` module reaches through imports (every
    import counted: inside functions and under ``if TYPE_CHECKING:`` too), one import chain
    ``[planner module, ..., testbed module]`` (the shortest found)."""
    graph = import_graph(root, deferred=True, type_checking=True)

    def within(module: str, names) -> bool:
        return any(module == n or module.startswith(n + ".") for n in names)

    starts = sorted(m for m in graph if within(m, PLANNER))
    prev: dict[str, str | None] = {m: None for m in starts}
    queue = list(starts)
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v]):
            if w not in prev:
                prev[w] = v
                queue.append(w)
    out = []
    for m in sorted(prev):
        if within(m, (TESTBED,)) and (prev[m] is None or not within(prev[m], (TESTBED,))):
            chain = [m]
            while prev[chain[-1]] is not None:
                chain.append(prev[chain[-1]])
            out.append(chain[::-1])
    return out


TESTS = ROOT.parents[1] / "tests"


def untested_modules(root: Path = ROOT, tests: Path = TESTS) -> list[str]:
    """Modules (paths relative to ``root``, ``__init__`` left out) that no test file
    (``tests/**/test_*.py``) imports: ``import a.b``, ``from a.b import x``, ``from a import b``,
    or a string naming the module (a ``monkeypatch`` target, ``importlib``)."""
    named: set[str] = set()
    for path in sorted(tests.rglob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                named.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                named.add(node.module)
                named.update(f"{node.module}.{alias.name}" for alias in node.names)
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                named.add(node.value)
    return sorted(path.relative_to(root).as_posix() for name, path in module_files(root).items()
                  if path.name != "__init__.py" and name not in named)


SHARED_NAMES = {
    "__init__": "a package's docstring",
    "config": "a package's settings (one frozen dataclass per stage or part)",
    "stage": "a plan stage package's entry: its cached run function (plan/discretize, similarity, score, place)",
    "types": "a package's shared hand-over types, kept apart from the modules that use them (plan, scene)",
}
"""File names (without ``.py``) that several modules may carry, each with its reason: the name
means the same thing in every package that has it. Any other name is one module's."""


def repeated_names(root: Path = ROOT) -> dict[str, list[str]]:
    """File name -> the modules (paths relative to ``root``'s parent) that share it, for every
    name not in :data:`SHARED_NAMES` carried by more than one module."""
    by_name: dict[str, list[str]] = {}
    for path in sorted(root.rglob("*.py")):
        if path.stem not in SHARED_NAMES:
            by_name.setdefault(path.stem, []).append(path.relative_to(root.parent).as_posix())
    return {name: paths for name, paths in sorted(by_name.items()) if len(paths) > 1}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted, largest first."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strong(w)
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
                out.append(sorted(comp))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                strong(v)
    finally:
        sys.setrecursionlimit(limit)
    return sorted(out, key=lambda c: (-len(c), c))


def cycle_path(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """One closed path a -> ... -> a through the component (for the report)."""
    comp = set(component)
    start = component[0]
    prev = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v] & comp):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return [start] + path[::-1][1:] + [start] if len(path) > 1 else [start, v, start]
            if w not in prev:
                prev[w] = v
                queue.append(w)
    return component


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, default=ROOT, help="package folder (default src/markerplace)")
    ap.add_argument("--max-lines", type=int, default=400, help="list modules over this many lines (default 400)")
    ap.add_argument("--fail-lines", type=int, default=None, help="exit 1 when a module is over this many lines")
    args = ap.parse_args(argv)

    files = module_files(args.root)
    sizes = line_counts(args.root)
    big = sorted(((n, m) for m, n in sizes.items() if n > args.max_lines), reverse=True)
    print(f"{len(sizes)} modules, {sum(sizes.values())} lines; over {args.max_lines} lines: {len(big)}")
    for n, m in big:
        print(f"  {n:5d}  {files[m].relative_to(args.root.parent)}")

    status = 0
    top = import_graph(args.root)
    top_cycles = cycles(top)
    print(f"import cycles at module level: {len(top_cycles)}")
    for comp in top_cycles:
        print("  " + " -> ".join(cycle_path(top, comp)) + (f"  ({len(comp)} modules)" if len(comp) > 2 else ""))
        status = 1
    full = import_graph(args.root, deferred=True)
    full_cycles = cycles(full)
    print(f"import cycles through imports inside functions: {len(full_cycles)}")
    for comp in full_cycles:
        print("  " + " -> ".join(cycle_path(full, comp)) + (f"  ({len(comp)} modules)" if len(comp) > 2 else ""))
    full_tc = import_graph(args.root, deferred=True, type_checking=True)
    tc_cycles = [c for c in cycles(full_tc) if c not in full_cycles]
    print(f"import cycles behind TYPE_CHECKING: {len(tc_cycles)}")
    for comp in tc_cycles:
        print("  " + " -> ".join(cycle_path(full_tc, comp)))
    pkg_cycles = package_cycles(full_tc)
    print(f"package-level cycles: {len(pkg_cycles)}")
    for comp in pkg_cycles:
        print("  " + " <-> ".join(comp))
    inner = deferred_imports(args.root)
    print(f"imports inside functions (other than {len(HEAVY_OPTIONAL)} heavy optional modules): {len(inner)}")
    for name, line, mod in inner[:40]:
        print(f"  {name}:{line}: {mod}")
    reach = planner_testbed_imports(args.root)
    print(f"testbed modules a plan imports: {len(reach)}")
    for chain in reach:
        print("  " + " -> ".join(chain))
    repeated = repeated_names(args.root)
    print(f"file names shared by several modules (other than {', '.join(sorted(SHARED_NAMES))}): {len(repeated)}")
    for name, paths in repeated.items():
        print(f"  {name}.py: {', '.join(paths)}")
    if full_cycles or tc_cycles or pkg_cycles or inner or repeated or reach:
        status = 1
    if args.fail_lines is not None and any(n > args.fail_lines for n, _ in big):
        status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
