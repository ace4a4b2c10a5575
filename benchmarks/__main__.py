"""`make bench`: every benchmark, one after the other on the same machine and commit.

Each benchmark runs as ``python -m benchmarks.NAME`` (its own process, so its numba, BLAS-thread and
subprocess set-up are its own; what it prints, its subprocesses' output included, is shown as it
comes) and its output is written, stamped with the date, the commit, the machine (cores, load) and
its command, to ``benchmarks/results/NAME.md``: the documentation's validation pages are made from
those files (``docs/validation/``). ``python -m benchmarks --only NAME[,NAME]`` runs some of them;
other arguments are passed to every benchmark.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path

from ._pages import ROOT, command_line, stamp, write_result

MODULES = ("bench_table1", "bench_simulator", "bench_estimator", "bench_analytics", "bench_operational", "bench_oma", "bench_dropbear", "bench_service",
           "bench_fleet", "bench_cluster", "bench_loads", "bench_bands", "bench_export", "fault_campaign", "kill_campaign", "http_campaign", "daq_fault_campaign")


def _title(name: str) -> str:
    import ast

    path = Path(__file__).with_name(f"{name}.py")
    doc = (ast.get_docstring(ast.parse(path.read_text())) or "").strip()
    first = doc.split("\n\n")[0].replace("\n", " ").strip().rstrip(".")
    return f"{name}: {first}" if first else name


def run(name: str, args: list[str]) -> int:
    """Run one benchmark, show and keep its output, write its stamped result; its exit status."""
    meta = stamp(command_line(name, args))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p),
           "PYTHONUNBUFFERED": "1"}
    t0 = time.monotonic()
    kept: list[str] = []
    with subprocess.Popen([sys.executable, "-m", f"benchmarks.{name}", *args], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True) as proc:
        assert proc.stdout is not None
        for line in proc.stdout:
            sys.stdout.write(line)
            sys.stdout.flush()
            kept.append(line)
    output = "".join(kept)
    if proc.returncode != 0:
        output += f"\n(exit status {proc.returncode}: the benchmark failed or a bar was not met)\n"
    write_result(name, _title(name), meta, output, time.monotonic() - t0)
    return proc.returncode


def main() -> int:
    args = sys.argv[1:]
    only = None
    if "--only" in args:
        i = args.index("--only")
        only = set(args[i + 1].split(","))
        unknown = only - set(MODULES)
        if unknown:
            print(f"benchmarks: unknown {sorted(unknown)}; the benchmarks are {', '.join(MODULES)}", file=sys.stderr)
            return 2
        args = args[:i] + args[i + 2:]
    failed = []
    for name in MODULES:
        if only is not None and name not in only:
            continue
        if importlib.util.find_spec(f"benchmarks.{name}") is None:
            continue
        if run(name, args) != 0:
            failed.append(name)
    if failed:
        print(f"benchmarks: {', '.join(failed)} exited non-zero (see their pages)", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
