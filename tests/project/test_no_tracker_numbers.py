"""No comment, docstring or page points at a tracker a reader of the repository cannot open:
a comment says why in its own words, the history is in the CHANGELOG's prose and the commits."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: "issue 21", "Issue 23's", "issues 6 and 10", "issue #5", also across a line break
TRACKER = re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE)
SKIP = {".venv", ".git", "site", "var", "build", "node_modules", ".pytest_cache"}


def _texts() -> list[Path]:
    out = []
    for path in ROOT.rglob("*"):
        rel = path.relative_to(ROOT)
        if set(rel.parts) & SKIP or not path.is_file():
            continue
        if path.suffix in {".py", ".md", ".toml", ".yml", ".yaml", ".cfg", ".txt"} or path.name == "Makefile":
            out.append(path)
    return out


def tracker_numbers(text: str) -> list[str]:
    """Every tracker reference in ``text``, as written."""
    return [m.group(0) for m in TRACKER.finditer(text)]


def test_the_pattern_finds_what_it_must_and_nothing_else():
    assert tracker_numbers("see issue 21, Issue 23's and issues 6 and 10; issue\n #5") == [
        "issue 21", "Issue 23", "issues 6", "issue\n #5"]
    assert tracker_numbers("an issue with 3 gauges? no: 'issue' then a word, tissue 4 is not one") == []


def test_no_tracker_numbers_in_code_docs_or_readme():
    this = Path(__file__).resolve()
    found = {str(p.relative_to(ROOT)): hits for p in _texts() if p.resolve() != this
             and (hits := tracker_numbers(p.read_text(encoding="utf-8", errors="replace")))}
    assert len(_texts()) > 100  # the walk found the repository
    assert not found, f"say why in words, history goes to the CHANGELOG's prose: {found}"
