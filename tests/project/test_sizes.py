"""No class over 300 lines and no function over 80 in ``shm_service/`` and ``web/`` (numba
kernels aside). Should one ever have to be over for a while, it is listed in DEBT with its size
(shrinking only: a listed one that grows fails too)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MAX_CLASS, MAX_FUNCTION = 300, 80

#: (path, qualified name) -> lines today
DEBT: dict[tuple[str, str], int] = {}  # none left


@functools.lru_cache(maxsize=1)
def _sizes() -> dict[tuple[str, str], tuple[str, int]]:
    """(path, qualified name) -> (kind, lines) of every class and function (numba kernels left out)."""
    out: dict[tuple[str, str], tuple[str, int]] = {}

    def visit(rel: str, node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                name = f"{prefix}{child.name}"
                if not any("jit" in ast.unparse(d) for d in child.decorator_list):
                    kind = "class" if isinstance(child, ast.ClassDef) else "function"
                    out[(rel, name)] = (kind, child.end_lineno - child.lineno + 1)
                visit(rel, child, f"{name}.")
            else:
                visit(rel, child, prefix)

    for package in ("shm_service", "web"):
        for path in sorted((ROOT / package).rglob("*.py")):
            visit(path.relative_to(ROOT).as_posix(), ast.parse(path.read_text(encoding="utf-8")), "")
    return out


def test_no_class_over_300_lines_and_no_function_over_80():
    over = []
    for (path, name), (kind, lines) in _sizes().items():
        limit = MAX_CLASS if kind == "class" else MAX_FUNCTION
        allowed = DEBT.get((path, name))
        if lines > limit and (allowed is None or lines > allowed):
            over.append(f"{path}: {kind} {name} has {lines} lines (limit {limit}" + (f", listed at {allowed})" if allowed else ")"))
    assert not over, "\n".join(over)

