"""Local damage found and placed: a 20 % bending-stiffness loss over 0.2 m appearing at 900 s of a
30-minute operational recording of the built-in lab sheet with a 20 K temperature swing, at
several positions along the beam, through the chain ``shm analyze`` runs (recording → estimator →
``shm_service.processing.analysis``, the baseline the record's own first trusted windows, learnt
before the damage).

Bars: flagged by 1500 s (within 600 s of the onset), the first flag's location (the damage
signatures' match) within 0.5 m of the damaged segment's centre; the healthy recording with the
same swing: no flag. Per position the table gives the first window in alarm, the charts in alarm,
the located η at the first flag and at the end, and the curvature chart's largest score after the
damage (which index carries the flag).

Recordings and b(t) are cached under var/bench/ (or $SHM_BENCH_CACHE).

Run: PYTHONPATH=. nice -n 10 .venv/bin/python -m benchmarks.bench_local_damage [--positions 1.0,2.5] [--seed 31] [--no-healthy]
(``--positions``: the segments' start in m, each 0.2 m long.)
"""

from __future__ import annotations

import sys

from benchmarks.bench_analytics import recording_path
from benchmarks.bench_operational import _analyse, _cached_deformations

DURATION = 1800.0
#: the damage's onset (s): after the record's own baseline (trusted windows from 180 s, armed at 660 s)
DAMAGE_AT = 900.0
#: the bars: flagged within this long after the onset (s), located within this distance (m)
DELAY_BAR_S = 600.0
PLACE_BAR_M = 0.5
SEGMENT_M = 0.2
#: segment starts (m) along the 4 m lab sheet: near the bearing, the upper third, the middle, lower
POSITIONS = (0.4, 1.0, 1.8, 2.5, 3.2)


def _log(*args) -> None:
    print(*args, flush=True)


def damage_row(name: str, res, centre: float | None) -> tuple[str, bool]:
    """The first flag after the onset, where it points, and whether the bars hold (healthy: no flag)."""
    if centre is None:
        ok = not res.flags
        return f"  {name:34s} flags {len(res.flags)}{'' if ok else '  <-- FALSE ALARM ' + str([(f['kind'], f['mode']) for f in res.flags])}", ok
    early = [f for f in res.flags if f["since_s"] is not None and f["since_s"] < DAMAGE_AT]
    ci = [w.curvature_score for w in res.windows if w.end_s > DAMAGE_AT and w.curvature_score is not None]
    ci_max = f"{max(ci):6.1f}" if ci else "  none"
    first = next((w for w in res.windows if w.flags and w.end_s > DAMAGE_AT), None)
    last = next((w.location for w in reversed(res.windows) if w.location is not None), None)
    end = "   -  " if last is None else f"{last.eta_m:5.2f} "
    if first is None:
        return f"  {name:34s} no flag            end η {end} m  curvature score max {ci_max} σ  <-- FAILS", False
    delay = first.end_s - DAMAGE_AT
    where = first.flags[0]
    eta = where.get("eta_m")
    placed = eta is not None and abs(eta - centre) <= PLACE_BAR_M
    ok = delay <= DELAY_BAR_S and placed and not early
    charts = sorted({f["kind"] + (str(f["mode"]) if f["mode"] else "") for f in first.flags})
    return (f"  {name:34s} flag at {first.end_s:5.0f} s (+{delay:4.0f} s, {','.join(charts)}) η {'  -  ' if eta is None else f'{eta:5.2f}'} m "
            f"({where.get('damage_kind')}, {where.get('located_by')})  end η {end} m  curvature score max {ci_max} σ"
            f"{'' if ok else '  <-- FAILS'}"), ok


def main(argv: list[str] | None = None) -> None:
    from shm_service.virtual_rig import SimulationSettings

    args = list(sys.argv[1:] if argv is None else argv)
    positions = [float(p) for p in args[args.index("--positions") + 1].split(",")] if "--positions" in args else list(POSITIONS)
    seed = int(args[args.index("--seed") + 1]) if "--seed" in args else 31
    base = dict(excitation="operational", duration=DURATION, temperature_swing=20.0, seed=seed)
    _log(f"bench_local_damage: 30-minute operational recordings, 20 K swing, seed {seed}, EI×0.8 over {SEGMENT_M} m from {DAMAGE_AT:.0f} s")
    cases: list[tuple[str, dict, float | None]] = [] if "--no-healthy" in args else [("healthy", {}, None)]
    for a in positions:
        b = a + SEGMENT_M
        cases.append((f"EI×0.8 @ {a:.1f}-{b:.1f} m", dict(damage=(f"stiffness:0.8@{a:g}-{b:g}",), damage_at=DAMAGE_AT), a + SEGMENT_M / 2))
    rows, verdict = [], {}
    for name, kw, centre in cases:
        rig, data, _ = _cached_deformations(recording_path(SimulationSettings(**base, **kw)))
        res, wall, _ = _analyse(rig, data)
        row, ok = damage_row(name, res, centre)
        _log(row)
        rows.append(row)
        verdict[name] = ok
    _log("\nbars: " + "; ".join(f"{k}: {'ok' if v else 'FAIL'}" for k, v in verdict.items()))


if __name__ == "__main__":
    main()
