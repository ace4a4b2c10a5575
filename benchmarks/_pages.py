"""The validation pages: each benchmark's output, stamped with when, on what and by what command it
was measured. ``make bench`` (``python -m benchmarks``) writes one file per benchmark into
``benchmarks/results/``; the documentation's hook (``docs_reference.py``) turns each into a page
of ``docs/validation/``, or a page saying it was not yet measured. A figure in the documentation is
then always one that a named command printed on a named commit and machine.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
import sys
from pathlib import Path

__all__ = ["RESULTS", "command_line", "stamp", "write_result"]

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return ""


def stamp(command: str) -> dict[str, str]:
    """When, on which commit and machine, and by which command a figure is measured."""
    # the results a run of `make bench` has already written are not a change of the code measured
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)benchmarks/results"))
    load = os.getloadavg()
    return {
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": (_git("rev-parse", "--short=12", "HEAD") or "unknown") + (" (with uncommitted changes)" if dirty else ""),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
                   f"Python {platform.python_version()}",
        "load": f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1/5/15 min) at the start",
        "command": command,
    }


def write_result(name: str, title: str, meta: dict[str, str], output: str, seconds: float) -> Path:
    """``benchmarks/results/NAME.md``: the stamp, then what the benchmark printed."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", "", "| measured | |", "| --- | --- |"]
    for key in ("date", "commit", "machine", "load", "command"):
        value = f"`{meta[key]}`" if key == "command" else meta[key]
        lines.append(f"| {key} | {value} |")
    lines.append(f"| took | {seconds:.0f} s |")
    lines += ["", "What the command printed:", "", "```text", output.rstrip() or "(nothing)", "```", ""]
    path = RESULTS / f"{name}.md"
    path.write_text("\n".join(lines))
    return path


def command_line(module: str, args: list[str]) -> str:
    return " ".join([Path(sys.executable).name, "-m", f"benchmarks.{module}", *args])
