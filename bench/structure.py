"""Structure of the code base (issues 26, 37): import cycles, modules per folder, which folders
import which, longest functions, widest signatures.

Reads the sources with the standard library's :mod:`ast` (nothing is imported or run):

* **import cycles**: strongly connected components (Tarjan) of the graph "module A imports
  module B" over the package's own modules, counting every import statement (module level and
  inside functions; ``--top-level`` counts module-level ones only).  ``from pkg import name``
  is an edge to ``pkg.name`` when that is a module, else to ``pkg``;
* **longest functions**: functions and methods by line count (``def`` to last line);
* **widest signatures**: by number of parameters (``self``/``cls`` not counted, ``*args`` and
  ``**kwargs`` counted once each).

Run: ``python bench/structure.py [--top N] [--top-level] [--packages physics nnmodel]``.
"""
from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def module_files(packages, root: Path = ROOT) -> dict[str, Path]:
    """{dotted module name: file} of every module under the given top-level packages of ``root``."""
    out = {}
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    """Absolute name of ``from <level dots><name> import …`` written in ``module``."""
    if level == 0:
        return name or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[:len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([name] if name else []))


def imports_of(module: str, path: Path, known: set[str], top_level: bool) -> set[str]:
    """The package modules that ``module`` imports."""
    tree = ast.parse(path.read_text(), filename=str(path))
    nodes = tree.body if top_level else list(ast.walk(tree))
    is_package = path.name == "__init__.py"
    out = set()

    def add(name):
        while name and name not in known:      # a name inside a module: the module holding it
            name = name.rpartition(".")[0]
        if name and name != module:
            out.add(name)

    for node in nodes:
        if isinstance(node, ast.Import):
            for a in node.names:
                add(a.name)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(module, is_package, node.level, node.module)
            for a in node.names:
                full = f"{base}.{a.name}" if base else a.name
                add(full if full in known else base)
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, comps, counter = {}, {}, set(), [], [], [0]
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        comps.append(sorted(comp))
    return sorted(comps, key=lambda c: (-len(c), c))


def functions(module: str, path: Path):
    """(qualified name, lines, parameters) of every function and method in ``path``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
                n = len([x for x in names if x not in ("self", "cls")]) + bool(a.vararg) + bool(a.kwarg)
                start = min([child.lineno] + [d.lineno for d in child.decorator_list])
                out.append((f"{module}.{prefix}{child.name}", child.end_lineno - start + 1, n))
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def folder_of(module: str, path: Path) -> str:
    """The folder holding a module (a package's ``__init__`` is in its own folder)."""
    return path.parent.relative_to(ROOT).as_posix()


def print_rooms(files: dict[str, Path], graph: dict[str, set[str]]) -> None:
    """Modules per folder, and which folders import which (the floors and rooms)."""
    count: dict[str, int] = {}
    for m, f in files.items():
        count[folder_of(m, f)] = count.get(folder_of(m, f), 0) + 1
    print("\nmodules per folder:")
    for d in sorted(count):
        print(f"  {count[d]:4d}  {d}/")
    edges: dict[str, set[str]] = {}
    for m, targets in graph.items():
        a = folder_of(m, files[m])
        for t in targets:
            b = folder_of(t, files[t])
            if a != b:
                edges.setdefault(a, set()).add(b)
    print("\nfolder -> folders it imports:")
    for a in sorted(edges):
        print(f"  {a}/ -> {', '.join(sorted(edges[a]))}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=15, help="how many functions to list (default 15)")
    ap.add_argument("--top-level", action="store_true", help="count module-level imports only")
    ap.add_argument("--packages", nargs="+", default=["physics", "nnmodel"])
    args = ap.parse_args(argv)
    files = module_files(args.packages)
    known = set(files)
    graph = {m: imports_of(m, f, known, args.top_level) for m, f in files.items()}
    comps = cycles(graph)
    n_lines = sum(len(f.read_text().splitlines()) for f in files.values())
    print(f"{len(files)} modules, {n_lines} lines in {', '.join(args.packages)}; "
          f"imports counted: {'module level only' if args.top_level else 'all (module level and in functions)'}")
    print(f"\nimport cycles: {len(comps)} (modules in cycles: {sum(map(len, comps))})")
    for c in comps:
        print(f"  {len(c):2d} modules: {', '.join(c)}")
    print_rooms(files, graph)
    funcs = [f for m, p in files.items() for f in functions(m, p)]
    print(f"\nlongest functions (of {len(funcs)}; lines):")
    for name, lines, _ in sorted(funcs, key=lambda f: (-f[1], f[0]))[:args.top]:
        print(f"  {lines:4d}  {name}")
    print("\nwidest signatures (parameters, self/cls not counted):")
    for name, _, n in sorted(funcs, key=lambda f: (-f[2], f[0]))[:args.top]:
        print(f"  {n:4d}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
