"""`make bench`: every benchmark in one run, so ratios are measured side by side.

Each benchmark's output is also written, stamped with the date, the commit, the machine (cores,
load) and its command, to ``benchmarks/results/NAME.md``: the documentation's validation pages
are made from those files (``docs/validation/``). ``python -m benchmarks --only NAME[,NAME]`` runs
some of them.
"""

from __future__ import annotations

import contextlib
import importlib
import sys
import time

from ._pages import Tee, command_line, stamp, write_result

MODULES = ("bench_simulator", "bench_estimator", "bench_analytics", "bench_operational", "bench_oma", "bench_service",
           "bench_fleet", "bench_loads", "fault_campaign", "kill_campaign", "http_campaign",
           "daq_fault_campaign")


def _title(module: object, name: str) -> str:
    doc = (getattr(module, "__doc__", None) or "").strip()
    first = doc.split("\n\n")[0].replace("\n", " ").strip().rstrip(".")
    return f"{name}: {first}" if first else name


def main() -> None:
    args = sys.argv[1:]
    only = None
    if "--only" in args:
        i = args.index("--only")
        only = set(args[i + 1].split(","))
        args = args[:i] + args[i + 2:]
    for name in MODULES:
        if only is not None and name not in only:
            continue
        try:
            module = importlib.import_module(f"benchmarks.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"benchmarks.{name}":
                continue
            raise
        meta = stamp(command_line(name, args))
        tee = Tee(sys.stdout)
        t0 = time.monotonic()
        with contextlib.redirect_stdout(tee):
            module.main(args)
        write_result(name, _title(module, name), meta, tee.getvalue(), time.monotonic() - t0)


if __name__ == "__main__":
    main()
