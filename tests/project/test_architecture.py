"""The import-cycle check and the tree map (``tools/architecture.py``) on small hand-made trees
whose cycles are known, and the map page against the folders."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def arch():
    spec = importlib.util.spec_from_file_location("architecture", ROOT / "tools" / "architecture.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["architecture"] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop("architecture", None)


def _tree(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_a_tree_without_cycles_passes(arch, tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": '"""A package."""\n', "pkg/low/__init__.py": "", "pkg/low/_a.py": "",
                     "pkg/high/__init__.py": "", "pkg/high/_b.py": "from ..low._a import x\n"})
    assert arch.cycles(arch.module_files(tmp_path, ("pkg",))) == []


def test_a_module_cycle_for_types_only_is_found(arch, tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": "", "pkg/_a.py": "from ._b import B\n",
                     "pkg/_b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ._a import A\n"})
    problems = arch.cycles(arch.module_files(tmp_path, ("pkg",)))
    assert any(p.startswith("module cycle: pkg._a -> pkg._b") for p in problems), problems


def test_a_package_cycle_without_a_module_cycle_is_found(arch, tmp_path):
    # low._a -> high._b and high._c -> low._d: no module reaches itself, but the rooms lean on each other
    _tree(tmp_path, {"pkg/__init__.py": "", "pkg/low/__init__.py": "", "pkg/high/__init__.py": "",
                     "pkg/low/_a.py": "def f():\n    from ..high._b import g\n", "pkg/high/_b.py": "",
                     "pkg/high/_c.py": "from ..low._d import h\n", "pkg/low/_d.py": ""})
    problems = arch.cycles(arch.module_files(tmp_path, ("pkg",)))
    assert not any(p.startswith("module cycle") for p in problems)
    assert any(p.startswith("package cycle: pkg:high, pkg:low") for p in problems), problems


def test_a_child_importing_its_parents_surface_is_no_cycle_unless_the_parent_imports_back(arch, tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": "from .sub import _x\n", "pkg/sub/__init__.py": "",
                     "pkg/sub/_x.py": "import pkg._base\n", "pkg/_base.py": ""})
    assert arch.cycles(arch.module_files(tmp_path, ("pkg",))) == []


def test_the_tree_map_lists_every_package_with_its_docstring(arch, tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": '"""Owns the pipes.\n\nMore."""\n', "pkg/a/__init__.py": '"""Owns a."""\n',
                     "pkg/a/_m.py": "import pkg.b._n\n", "pkg/b/__init__.py": '"""Owns b."""\n', "pkg/b/_n.py": ""})
    page = arch.tree_map(arch.module_files(tmp_path, ("pkg",)))
    assert "| `pkg` | 2 | Owns the pipes. | — |" in page
    assert "| `pkg.a` | 1 | Owns a. | `pkg.b` |" in page
    assert "| `pkg.b` | 1 | Owns b. | — |" in page


def test_every_folder_of_the_service_and_web_holds_at_most_15_modules():
    crowded = {str(d.relative_to(ROOT)): n for top in ("shm_service", "web") for d in [ROOT / top, *(ROOT / top).rglob("*")]
               if d.is_dir() and "__pycache__" not in d.parts and (n := len(list(d.glob("*.py")))) > 15}
    assert not crowded, crowded


def test_the_tree_map_page_matches_the_folders(arch):
    page = ROOT / "docs" / "development" / "tree.md"
    assert page.read_text() == arch.tree_map(), "run python tools/architecture.py --write"
