"""No import cycle between the project's modules, including imports inside functions and those
under ``if TYPE_CHECKING:`` (the graph and the finder are ``tools/architecture.py``'s, whose own
tests on hand-made trees are in ``test_architecture.py``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _architecture():
    spec = importlib.util.spec_from_file_location("_architecture_for_cycles", ROOT / "tools" / "architecture.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_project_has_no_module_import_cycle():
    cycles = [p for p in _architecture().cycles() if p.startswith("module cycle")]
    assert not cycles, "\n".join(cycles)


def test_the_cycle_finder_finds_a_cycle():
    arch = _architecture()
    assert arch._strongly_connected({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert arch._strongly_connected({"a": {"b"}, "b": set()}) == []
