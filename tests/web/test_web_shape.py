"""The shape of ``web/`` that its maintainers rely on: no class over 300 lines and no
function over 80, every HTML text built in ``web/_html.py``, and no import cycle between its
modules (counting the imports made only for type checking)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

WEB = Path(__file__).resolve().parents[2] / "web"
#: an HTML tag in a string literal
TAG = re.compile(r"<(p|div|span|b|br|table|tr|td|th|i|sub)[\s>/]")


def _modules() -> dict[str, ast.Module]:
    return {p.stem: ast.parse(p.read_text(encoding="utf-8")) for p in sorted(WEB.glob("*.py"))}


def test_no_class_over_300_lines_and_no_function_over_80():
    too_long = [
        f"{name}.py:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"
        for name, tree in _modules().items() for node in ast.walk(tree)
        if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        and node.end_lineno - node.lineno + 1 > (300 if isinstance(node, ast.ClassDef) else 80)
    ]
    assert not too_long, too_long


def test_html_is_built_in_one_module():
    outside = [
        f"{name}.py:{node.lineno}"
        for name, tree in _modules().items() if name != "_html" for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and TAG.search(node.value)
        and not (isinstance(node, ast.Constant) and node.col_offset == 0)  # (a module docstring)
    ]
    assert not outside, f"HTML built outside web/_html.py: {outside}"


def test_no_import_cycle_between_webs_modules():
    graph = {name: {node.module.lstrip(".").split(".")[0] for node in ast.walk(tree)
                    if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module}
             for name, tree in _modules().items()}

    def reach(start: str, seen: set[str]) -> set[str]:
        for nxt in graph.get(start, ()):
            if nxt not in seen:
                seen.add(nxt)
                reach(nxt, seen)
        return seen

    cycles = sorted(name for name in graph if name in reach(name, set()))
    assert not cycles, f"modules on an import cycle: {cycles}"
