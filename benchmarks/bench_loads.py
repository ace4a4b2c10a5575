"""Cost of the loads (issue 21): the streaming rainflow count per structure-second, next to the
`rainflow` package (ASTM E1049 three-point, whole records) on the same signals.

A structure here is one hour at 200 Hz of a narrow-band strain signal at each of 4 hot spots (the
signal of a lightly damped beam's first modes plus noise), counted in 10 s windows the way the
engine counts (HotSpotFatigue: streaming count, window DEL, Miner damage on an EN 1993-1-9 curve).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_loads.py [--quick]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from analytics import FatigueDetail, HotSpotFatigue, rainflow_cycles, sn_curve

FS = 200.0
HOT_SPOTS = 4


def _signal(seconds: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = int(seconds * FS)
    t = np.arange(n) / FS
    # three modes with slowly wandering amplitude plus broadband noise, ~40 MPa
    amp = 1 + 0.3 * np.convolve(rng.normal(size=n), np.ones(2000) / 2000 ** 0.5, mode="same") / 10
    x = sum(a * amp * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for a, f in ((30e6, 0.86), (12e6, 1.9), (5e6, 3.5)))
    return x + 2e6 * rng.normal(size=n)


def main(argv: list[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    seconds = 600.0 if "--quick" in args else 3600.0
    window = int(10 * FS)
    signals = [_signal(seconds, seed) for seed in range(HOT_SPOTS)]
    detail = FatigueDetail(sn_curve("EN1993-1-9:71"), gamma_mf=1.35)

    t0 = time.process_time()
    import pylife.stress.rainflow  # noqa: F401  (pandas: a one-off cost per process, reported apart)

    imported = time.process_time() - t0
    t0 = time.process_time()
    damage = []
    for x in signals:
        spot = HotSpotFatigue(detail)
        for k in range(0, x.size, window):
            spot.push(x[k:k + window], window / FS)
        damage.append(spot.consumed)
    ours = time.process_time() - t0

    t0 = time.process_time()
    for x in signals:
        rainflow_cycles(x)
    whole = time.process_time() - t0

    import rainflow

    t0 = time.process_time()
    reference = []
    for x in signals:
        reference.append(sum(c for _r, _m, c, _i, _j in rainflow.extract_cycles(x)))
    theirs = time.process_time() - t0

    per = 1e6 / seconds  # µs per structure-second
    print(f"bench_loads: {HOT_SPOTS} hot spots x {seconds:.0f} s at {FS:.0f} Hz per structure (CPU time)")
    print(f"  streaming count in 10 s windows + window DEL + Miner damage: {ours * per:8.1f} µs per structure-second")
    print(f"  our count of the whole record (pyLife four-point + residue):  {whole * per:8.1f} µs per structure-second")
    print(f"  the `rainflow` package, whole record (count only):             {theirs * per:8.1f} µs per structure-second")
    print(f"  share of one core for 100 structures at real time: {100 * ours / seconds:.2%} (ours), {100 * theirs / seconds:.2%} (rainflow)")
    print(f"  one-off import of pyLife (pandas) per process: {imported:.2f} s CPU")
    print(f"  consumed D per hour: {', '.join(f'{d:.3e}' for d in damage)}")


if __name__ == "__main__":
    main()
