"""The simulator's speed bar: 300 s of the default layout must simulate in under 30 s on one core.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_simulator
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from shm_service.recording import read_recording
from shm_service.virtual_rig import SimulationSettings, simulate


def main(argv: list[str] | None = None) -> None:
    print("\n== virtual rig: simulate and write 300 s (one process, one core) ==")
    with tempfile.TemporaryDirectory() as tmp:
        simulate(SimulationSettings(duration=5), Path(tmp) / "warm.mcap")  # compile once (numba cache)
        for layout in ("benchmark", "dense"):
            path = Path(tmp) / f"{layout}.mcap"
            started = time.perf_counter()
            summary = simulate(SimulationSettings(duration=300, layout=layout), path)
            wall = time.perf_counter() - started
            started = time.perf_counter()
            rec = read_recording(path)
            read = time.perf_counter() - started
            n = sum(summary.messages.values())
            print(f"{layout:9}: {n} messages, simulate+write {wall:5.1f} s ({300 / wall:4.0f}x real time), "
                  f"read {read:4.1f} s ({n / read / 1000:.0f}k msg/s), {path.stat().st_size / 1e6:.0f} MB, "
                  f"problems: {len(rec.report.problems)}")


if __name__ == "__main__":
    main()
