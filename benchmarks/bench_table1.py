"""The beam model against the paper's Table 1: the FE model's eigenfrequencies of the paper's rig
(the calibrated 4 m sheet, pinned at D, hanging) next to the measured ones the paper lists, as
``shm modes --json`` prints them.

Run: PYTHONPATH=. .venv/bin/python -m benchmarks.bench_table1
"""

from __future__ import annotations

import json
import subprocess
import sys


def main(argv: list[str] | None = None) -> None:
    print("\n== the beam model against the paper's Table 1 (shm modes --json) ==")
    out = subprocess.run([sys.executable, "-m", "shm_service.cli", "modes", "--json"], capture_output=True, text=True, check=True)
    modes = json.loads(out.stdout)
    print(f"rig: {modes['support']}, {modes['orientation']}, L = {modes['length_m']} m, g = {modes['gravity']} m/s²")
    print(f"{'mode':>4} {'model Hz':>10} {'Table 1 Hz':>11} {'error %':>8}")
    for k, (f, t, e) in enumerate(zip(modes["frequencies_hz"], modes["table1_hz"], modes["relative_error"]), start=1):
        print(f"{k:>4} {f:>10.4f} {t:>11.3f} {100 * e:>+8.2f}")
    worst = max(abs(e) for e in modes["relative_error"][:4])
    print(f"largest error of modes 1-4: {100 * worst:.2f} % (modes 1-4 weigh 1 in the calibration, modes 5-6 0.1)")


if __name__ == "__main__":
    main()
