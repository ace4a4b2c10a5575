"""Bars of issue 5 on the virtual rig, with b from the least-squares projection of the truth
deflection onto the unit deformations (no estimator yet). Prints figures.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_analytics.py [--quick]
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from analytics import AnalysisConfig, analyze
from estimator import assemble_beam, unit_deformations
from shm_service.virtual_rig import PlantSettings, SimulationSettings, VirtualRig


def record(**kw):
    vr = VirtualRig(SimulationSettings(ideal=True, **kw))
    units = unit_deformations(assemble_beam(vr.nominal_rig), 4)
    st = np.asarray(vr.nominal_rig.truth_stations)
    S = units.shape(st)
    T, B, TT, TV, BT, BV = [], [], [], [], [], []
    for blk in vr.blocks(60.0):
        B.append(np.linalg.lstsq(S, blk.truth["deflection"].T, rcond=None)[0].T)
        T.append(blk.times)
        m = blk.measurements
        if "/env/temperature" in m:
            TT.append(m["/env/temperature"][0]); TV.append(m["/env/temperature"][1][:, 0])
        if "/bearing/displacement" in m:
            BT.append(m["/bearing/displacement"][0]); BV.append(m["/bearing/displacement"][1][:, 0])
    t = np.concatenate(T)
    rec = dict(t=t, b=np.vstack(B), curv=units.curvature(st), stations=st, expected=units.frequencies_hz,
               temperature=(np.concatenate(TT), np.concatenate(TV)) if TT else None,
               bearing=np.interp(t, np.concatenate(BT), np.concatenate(BV)) if BT else None, meta=vr.truth_metadata())
    return rec


def run(rec, **kw):
    t0 = time.perf_counter()
    res = analyze(rec["t"], rec["b"], rec["curv"], rec["stations"], expected_hz=rec["expected"],
                  temperature=rec["temperature"], bearing=kw.pop("bearing", None), **kw)
    return res, time.perf_counter() - t0


def frequencies(name, rec, res):
    exact = json.loads(rec["meta"]["eigenfrequencies_hz"])
    print(f"\n[{name}] eigenfrequencies (exact = linearised plant)")
    for m in res.modes:
        f = m.frequency_hz
        err = 100 * (f / exact[m.mode - 1] - 1) if f else float("nan")
        sd = 100 * (m.frequency_std_hz or float("nan")) / (f or 1)
        print(f"  mode {m.mode} (unit {m.unit}): {f:.5f} Hz  exact {exact[m.mode - 1]:.5f}  err {err:+.3f} %  1σ {sd:.3f} %  windows {m.windows}")


def damping(name, rec, res):
    z = json.loads(rec["meta"]["modal_damping_ratios"])
    print(f"\n[{name}] damping")
    for m in res.modes:
        if m.damping_ratio is None:
            print(f"  mode {m.mode}: none"); continue
        print(f"  mode {m.mode}: ζ={m.damping_ratio:.5f} ± {m.damping_std:.5f} ({m.damping_method})  sim {z[m.mode - 1]:.4f}  err {100 * (m.damping_ratio / z[m.mode - 1] - 1):+.1f} %")


def flags(name, rec, res, damage_at=None):
    print(f"\n[{name}] flags: {len(res.flags)}")
    for f in res.flags:
        late = "" if damage_at is None or f["since_s"] is None else f"  (onset {f['since_s'] - damage_at:+.0f} s after damage)"
        print(f"  {f}{late}")
    alarms = [w.end_s for w in res.windows if w.flags]
    if damage_at is not None:
        first = min((a for a in alarms if a >= damage_at), default=None)
        print(f"  first alarm at {first} s, i.e. {None if first is None else first - damage_at:.0f} s after damage" if first else "  no alarm after damage")
        cur = [w for w in res.windows if w.curvature is not None and w.end_s > damage_at + 300]
        if cur:
            thirds = [w.curvature.third for w in cur]
            print("  curvature index third after damage:", {k: thirds.count(k) for k in set(thirds)}, " final η:", cur[-1].curvature.eta_m)
    if res.baseline:
        print("  baseline slopes %/K:", [round(100 * m.slope_per_k, 4) for m in res.baseline.modes],
              " σ_rel %:", [round(100 * m.sigma_rel, 3) for m in res.baseline.modes])


def main(argv: list[str] | None = None) -> None:
    quick = "--quick" in (sys.argv[1:] if argv is None else argv)
    dur = 900 if quick else 1800
    t = time.perf_counter()
    amb = record(duration=dur, excitation="ambient", temperature_swing=20.0, seed=1)
    print(f"sim ambient {dur} s: {time.perf_counter() - t:.0f} s")
    res, dt = run(amb)
    print(f"analyze: {dt:.1f} s")
    frequencies("ambient ±10 K, default ambient_force 0.4 N", amb, res)
    damping("ambient (random decrement)", amb, res)
    flags("healthy ambient ±10 K", amb, res)
    low = record(duration=dur, excitation="ambient", temperature_swing=20.0, seed=2, plant=PlantSettings(ambient_force=0.04))
    res, _ = run(low)
    frequencies("ambient ±10 K, ambient_force 0.04 N (near-linear amplitudes)", low, res)
    flags("healthy ambient low force", low, res)
    dec = record(duration=dur, excitation="decay", seed=1)
    res, _ = run(dec, bearing=dec["bearing"])
    frequencies("decay (bearing given)", dec, res)
    damping("decay (bearing given)", dec, res)
    res, _ = run(dec)
    damping("decay (no bearing signal)", dec, res)
    for dmg in ("mass:0.126@4.0", "stiffness:0.8@1.0-1.2"):
        rec = record(duration=dur, excitation="ambient", temperature_swing=20.0, seed=3, damage=(dmg,), damage_at=600.0)
        after = json.loads(rec["meta"]["eigenfrequencies_after_damage_hz"])
        before = json.loads(rec["meta"]["eigenfrequencies_hz"])
        print(f"\n{dmg}: exact shifts %:", [round(100 * (a / b - 1), 3) for a, b in zip(after[:5], before[:5])])
        res, _ = run(rec)
        flags(dmg, rec, res, damage_at=600.0)


if __name__ == "__main__":
    main()
