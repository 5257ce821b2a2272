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

Exit status 1 when there is a top-level cycle or a module over ``--fail-lines`` (when given),
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


def _imports(tree: ast.Module):
    """(node, deferred) for every import statement; deferred = inside a function."""

    def walk(nodes, deferred):
        for node in nodes:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                yield node, deferred
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                yield from walk(ast.iter_child_nodes(node), True)
            elif isinstance(node, ast.If) and _is_type_checking(node.test):
                yield from walk(node.orelse, deferred)
            else:
                yield from walk(ast.iter_child_nodes(node), deferred)

    yield from walk(tree.body, False)


def _with_parents(name: str, modules: dict[str, Path]) -> list[str]:
    """``a.b.c`` -> the known modules among ``a``, ``a.b``, ``a.b.c``."""
    parts = name.split(".")
    return [m for m in (".".join(parts[:i]) for i in range(1, len(parts) + 1)) if m in modules]


def import_graph(root: Path = ROOT, deferred: bool = False) -> dict[str, set[str]]:
    """Module -> modules of the package it imports (at module level; also inside functions
    when ``deferred``). Self-edges of a package's ``__init__`` to its own parents are dropped."""
    modules = module_files(root)
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        is_pkg = path.name == "__init__.py"
        package = name if is_pkg else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node, inner in _imports(tree):
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
    if args.fail_lines is not None and any(n > args.fail_lines for n, _ in big):
        status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
