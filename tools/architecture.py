"""The project's architecture from its sources: the import graph, its cycles and the map of the tree.

``python tools/architecture.py --check`` fails (exit 1) on an import cycle of any kind, or when
``docs/development/tree.md`` no longer matches the folders; ``--write`` regenerates that page.

Every import counts, wherever it stands: at the top, inside a function (a lazy import still ties
the two modules together) and under ``TYPE_CHECKING`` (a cycle for types only is still a cycle a
reader has to hold in their head). Two kinds of cycle are refused:

- between modules: a module that reaches itself through what it imports;
- between packages: for an import from module ``a`` to module ``b``, the two siblings under their
  lowest common package that hold ``a`` and ``b`` (a subpackage, or a module directly in that
  package) get an edge; a cycle among siblings means two rooms that lean on each other, even when
  no single module does.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: the packages of the project, in the order of their layers (lowest first)
PACKAGES = ("contract", "estimator", "analytics", "shm_service", "web", "benchmarks")
TREE_PAGE = ROOT / "docs" / "development" / "tree.md"


def module_files(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Every module of the packages under ``root`` by its dotted name (a package by its ``__init__``)."""
    out: dict[str, Path] = {}
    for top in packages:
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _is_package(name: str, files: dict[str, Path]) -> bool:
    return files[name].name == "__init__.py"


def import_graph(files: dict[str, Path]) -> dict[str, set[str]]:
    """The modules each module imports (project modules only), from every import statement in it."""
    graph: dict[str, set[str]] = {name: set() for name in files}
    for name, path in files.items():
        package = name if _is_package(name, files) else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - node.level + 1]
                    source = ".".join(base + ([node.module] if node.module else []))
                else:
                    source = node.module or ""
                targets = [f"{source}.{alias.name}" if f"{source}.{alias.name}" in files else source
                           for alias in node.names]
            for target in targets:
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's components with more than one node, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0

    def visit(root: str) -> None:
        nonlocal counter
        work = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
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

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def _sibling_pair(a: str, b: str, files: dict[str, Path]) -> tuple[str, str] | None:
    """The siblings under the lowest common package of ``a`` and ``b`` that hold them, or None
    when one contains the other (a package's ``__init__`` counts as a sibling named ``__init__``)."""
    pa, pb = a.split("."), b.split(".")
    if _is_package(a, files):
        pa = pa + ["__init__"]
    if _is_package(b, files):
        pb = pb + ["__init__"]
    i = 0
    while i < min(len(pa), len(pb)) and pa[i] == pb[i]:
        i += 1
    if i == len(pa) or i == len(pb):
        return None
    prefix = ".".join(pa[:i])
    return f"{prefix}:{pa[i]}", f"{prefix}:{pb[i]}"


def cycles(files: dict[str, Path] | None = None) -> list[str]:
    """Every import cycle of the project, one line each (empty when there is none)."""
    files = module_files() if files is None else files
    graph = import_graph(files)
    problems = [f"module cycle: {' -> '.join(c)}" for c in _strongly_connected(graph)]
    siblings: dict[str, set[str]] = defaultdict(set)
    for a, targets in graph.items():
        for b in targets:
            pair = _sibling_pair(a, b, files)
            if pair is not None:
                siblings[pair[0]].add(pair[1])
    for component in _strongly_connected(siblings):
        witnesses = sorted(f"{a} -> {b}" for a, targets in graph.items() for b in targets
                           if (pair := _sibling_pair(a, b, files)) is not None
                           and pair[0] in component and pair[1] in component)
        problems.append(f"package cycle: {', '.join(component)} (through {'; '.join(witnesses[:6])})")
    return problems


def _summary(path: Path) -> str:
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return " ".join(doc.split("\n\n")[0].split())


def tree_map(files: dict[str, Path] | None = None) -> str:
    """The page ``docs/development/tree.md``: every package, what it owns, what it imports."""
    files = module_files() if files is None else files
    graph = import_graph(files)
    lines = [
        "# A map of the tree",
        "",
        "Generated from the packages' docstrings and imports by `python tools/architecture.py --write`;",
        "`make check` fails when this page and the folders disagree, and on any import cycle.",
        "Data flows one way: source → reader → estimator → analytics → storage, alarms, API, dashboard;",
        "each package below imports only those listed beside it (within the project).",
        "",
        "| package | modules | owns | imports |",
        "| --- | --- | --- | --- |",
    ]
    packages = sorted(n for n in files if _is_package(n, files))
    for package in packages:
        members = [n for n in files if n.startswith(package + ".") and n.count(".") == package.count(".") + 1]
        inside = [n for n in files if n == package or n.startswith(package + ".")]
        uses = set()
        for module in inside:
            for target in graph[module]:
                if target == package or target.startswith(package + "."):
                    continue
                owner = target if _is_package(target, files) else target.rpartition(".")[0]
                # a module of an enclosing package is named itself: its package would say too much
                uses.add(target if package.startswith(owner + ".") else owner)
        shown = sorted(uses)
        lines.append(f"| `{package}` | {len(members)} | {_summary(files[package]).replace('|', '/')} | "
                     f"{', '.join(f'`{u}`' for u in shown) or '—'} |")
    lines += [
        "",
        "## Where to add",
        "",
        "- a data source: a module in `shm_service/service/sources/` (a subclass of a source there);",
        "- a stage of a structure's pipeline: a module in `shm_service/service/stages/`, wired in `_pipeline`;",
        "- an HTTP route: a module in `shm_service/service/http/routes/`, listed in its `ROUTERS`;",
        "- a storage backend: a folder beside `shm_service/service/storage/sqlite/`;",
        "- an input format: a module in `shm_service/formats/`;",
        "- a command: its work in `shm_service/commands/`, its arguments in `shm_service/cli.py`.",
        "",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--check", action="store_true", help="fail on a cycle or a stale tree map")
    group.add_argument("--write", action="store_true", help="regenerate docs/development/tree.md")
    args = parser.parse_args(argv)
    if args.write:
        TREE_PAGE.write_text(tree_map())
        print(f"wrote {TREE_PAGE.relative_to(ROOT)}")
        return 0
    problems = cycles()
    if not TREE_PAGE.exists() or TREE_PAGE.read_text() != tree_map():
        problems.append(f"{TREE_PAGE.relative_to(ROOT)} does not match the folders: "
                        "run python tools/architecture.py --write")
    for problem in problems:
        print(problem, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
