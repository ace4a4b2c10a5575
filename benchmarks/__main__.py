"""`make bench`: every benchmark in one run, so ratios are measured side by side."""

from __future__ import annotations

import importlib
import sys

MODULES = ("bench_simulator", "bench_estimator", "bench_analytics", "bench_operational", "bench_oma", "bench_service",
           "bench_fleet", "bench_loads", "fault_campaign", "kill_campaign", "http_campaign")


def main() -> None:
    args = sys.argv[1:]
    for name in MODULES:
        try:
            module = importlib.import_module(f"benchmarks.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"benchmarks.{name}":
                continue
            raise
        module.main(args)


if __name__ == "__main__":
    main()
