"""The DROPBEAR figures: 0.5 s windows every 0.25 s, band 15–80 Hz, the windows whose
acceleration RMS is at least 5× the trial's quietest; the lowest listed mode of each window
against the roller position (PinLoc): slow steps (dwell windows, PinLoc std ≤ 0.01 V) the
relative RMS residual of a cubic fit, random dwell the Spearman rank correlation; and the share
of counted windows with a mode. Also the naive peak picker (the largest amplitude-spectrum peak
in the band) on the same windows for comparison.

Run: PYTHONPATH=. python -m benchmarks.bench_dropbear [--data DIR] [--channels accel|all] [trial ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal, stats

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "dropbear"
TRIALS = [f"{p}/test{k}" for p in ("slow-steps", "random-dwell") for k in range(3)]


def evaluate(path: Path, channels: str = "accel", window: float = 0.5, step: float = 0.25) -> dict:
    from analytics import OmaConfig, OperationalModalAnalysis
    from shm_service.formats.tables import read_table

    table = read_table(path)
    names = ["Low G Accel"] + ([c for c in ("SG_300_a", "SG_306_b") if c in table.channels] if channels == "all" else [])
    y = table.data[:, [table.channels.index(c) for c in names]]
    acc = table.data[:, table.channels.index("Low G Accel")]
    pin = table.data[:, table.channels.index("PinLoc")]
    fs = table.fs_hz
    t0 = time.perf_counter()
    res = OperationalModalAnalysis(OmaConfig(fmin_hz=15, fmax_hz=80), window_s=window, step_s=step, whole_record=False).run(y, fs)
    secs = time.perf_counter() - t0
    f, naive, rms, pm, ps, nmodes, moving = [], [], [], [], [], [], []
    for w in res.windows:
        a, b = round(w.start_s * fs), round(w.end_s * fs)
        ms = [m for m in w.modes if 15 <= m.frequency_hz <= 80]
        f.append(min((m.frequency_hz for m in ms), default=np.nan))
        moving.append(any(getattr(m, "moving", False) for m in ms))
        nmodes.append(len(ms))
        x = signal.detrend(acc[a:b])
        nf = 1 << 16
        spec = np.abs(np.fft.rfft(x * np.hanning(x.size), nf))
        fr = np.fft.rfftfreq(nf, 1 / fs)
        band = (fr >= 15) & (fr <= 80)
        naive.append(fr[band][np.argmax(spec[band])])
        rms.append(np.std(acc[a:b]))
        pm.append(np.mean(pin[a:b]))
        ps.append(np.std(pin[a:b]))
    f, naive, rms, pm, ps = map(np.array, (f, naive, rms, pm, ps))
    counted = rms >= 5 * rms.min()
    slow = "slow-steps" in str(path)
    if slow:
        counted &= ps <= 0.01
    found = counted & np.isfinite(f)
    out = {"windows": len(f), "counted": int(counted.sum()), "found": float(found.sum() / max(1, counted.sum())), "seconds": secs,
           "mean_modes": float(np.mean(np.array(nmodes)[counted])), "moving": int(np.sum(np.array(moving)[counted]))}

    def figure(v, sel):
        if slow:
            coef = np.polyfit(pm[sel], v[sel], 3)
            r = v[sel] / np.polyval(coef, pm[sel]) - 1
            return float(np.sqrt(np.mean(r ** 2)))
        return float(stats.spearmanr(v[sel], pm[sel]).statistic)

    out["figure"] = figure(f, found)
    out["naive"] = figure(naive, counted)
    out["kind"] = "residual" if slow else "rank"
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("trials", nargs="*", default=TRIALS)
    p.add_argument("--data", type=Path, default=DATA)
    p.add_argument("--channels", choices=("accel", "all"), default="accel")
    a = p.parse_args(argv)
    for t in a.trials:
        r = evaluate(a.data / f"{t}.txt", a.channels)
        fig = f"{100 * r['figure']:.3f} %" if r["kind"] == "residual" else f"rho {r['figure']:.4f}"
        nv = f"{100 * r['naive']:.3f} %" if r["kind"] == "residual" else f"rho {r['naive']:.4f}"
        print(f"{t:22s} {a.channels:5s} counted {r['counted']:3d}/{r['windows']:3d} found {100 * r['found']:5.1f} %  "
              f"lowest mode: {fig:>12s}  naive: {nv:>12s}  modes/window {r['mean_modes']:.2f}  moving {r['moving']}  {r['seconds']:.1f} s",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
