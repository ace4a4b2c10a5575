"""The monitoring bars through the real chain: simulate → estimator (shm_service.processing.estimation.
deformation_record) → analytics.analyze, with a peer operational modal analysis (pyOMA-2,
SSI-cov on the raw IMU accelerations) side by side.

Bars: ambient 30 min eigenfrequencies vs the simulator's exact values; decay 30 min damping
ratios vs the simulated modal damping; damage (1 % beam mass at the tip; 20 % EI loss over
1.0–1.2 m) appearing at 900 s of an 1800 s ambient run with a ±10 K temperature swing → time
to the first flag and the located third (the baseline is the record's first 480 s of trusted
windows, learnt by 660 s: before the damage); healthy ±10 K runs → no flag. All on the realistic
default plant (model mismatch, IMU scale and misalignment errors, bias wander; `--ideal` for the
idealised one). For information, not a bar: the same ambient and decay runs with the study's
bearing friction (0.03 N·m Coulomb), whose stick-slip the linear "exact" figures do not describe.

Recordings and the estimator's b(t) are cached under var/bench/ (or $SHM_BENCH_CACHE), keyed
by the simulation settings, so reruns take seconds. pyOMA-2 is installed into the running
interpreter with pip when missing (it is not a project dependency).

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_analytics.py [--quick] [--seeds 3,4] [--healthy-seeds 2,5,6] [--no-peer] [--ideal]
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analytics import analyze
from estimator import damage_signatures, parse_rig
from shm_service.study import StudySettings
from shm_service.virtual_rig import SimulationSettings

#: the study's bearing friction (N·m), whose effect the benchmark shows for information
STUDY_FRICTION = StudySettings.model_fields["friction_torque"].default

PEER_PACKAGE = "pyOMA-2"  # import name pyoma2

#: when the damage appears in the damage runs (s): after the baseline (armed at 660 s)
DAMAGE_AT = 900.0


def _log(*args) -> None:
    print(*args, flush=True)


CACHE = Path(os.environ.get("SHM_BENCH_CACHE", "var/bench"))


def _key(settings) -> str:
    # defaults left out: a new settings field with a default keeps the old recordings' keys
    text = json.dumps(settings.model_dump(mode="json", exclude_defaults=True), sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def recording_path(settings, *, log=_log) -> Path:
    """The recording of ``settings`` (simulated now unless cached)."""
    from shm_service.virtual_rig import simulate

    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"rec_{_key(settings)}.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        tmp = path.with_suffix(".part.mcap")
        simulate(settings, tmp)
        tmp.rename(path)
        log(f"  simulated {settings.excitation} {settings.duration:.0f} s seed {settings.seed} in {time.perf_counter() - t0:.0f} s → {path}")
    return path


@dataclass(frozen=True)
class Deformations:
    """b(t) of a recording through the estimator, with what analytics.analyze needs."""

    times: np.ndarray
    b: np.ndarray
    curvature_shapes: np.ndarray
    stations: np.ndarray
    expected_hz: tuple
    temperature: tuple | None
    bearing: np.ndarray | None
    truth: dict
    rig_json: str
    beam_length: float
    estimator_s: float
    path: Path
    support: np.ndarray | None = None  # the estimator's d(t): the measured input (shm analyze's)
    origin_ns: int = 0
    rest_end_s: float | None = None


def deformations(settings, *, log=_log) -> Deformations:
    """Simulate (cached) → shm_service.processing.estimation.deformation_record (cached) for ``settings``."""
    path = recording_path(settings, log=log)
    npz = path.with_suffix(".b.npz")
    if npz.exists() and "support" not in np.load(npz).files:  # cached before the support was kept
        npz.unlink()
    if not npz.exists():
        from shm_service.processing.estimation import deformation_record
        from shm_service.recording import read_recording

        t0 = time.perf_counter()
        rec = read_recording(path)
        data = deformation_record(rec)
        dt = time.perf_counter() - t0
        temp = data.temperature
        np.savez(
            npz.with_suffix(".part.npz"), times=data.times, b=data.b, curvature=data.units.curvature(data.stations),
            stations=data.stations, expected=json.dumps(data.units.frequencies_hz),
            temp_t=temp[0] if temp else np.zeros(0), temp_v=temp[1] if temp else np.zeros(0),
            bearing=data.bearing if data.bearing is not None else np.zeros(0),
            truth=json.dumps(data.truth_metadata or {}), rig=rec.rig.to_json(), length=rec.rig.beam.length, estimator_s=dt,
            support=data.support, origin=np.int64(data.origin_ns), rest_end=data.rest_end_s,
        )
        npz.with_suffix(".part.npz").rename(npz)
        log(f"  estimator on {path.name}: {dt:.0f} s")
    z = np.load(npz, allow_pickle=False)
    return Deformations(
        z["times"], z["b"], z["curvature"], z["stations"], tuple(tuple(g) for g in json.loads(str(z["expected"]))),
        (z["temp_t"], z["temp_v"]) if z["temp_t"].size >= 2 else None, z["bearing"] if z["bearing"].size else None,
        json.loads(str(z["truth"])), str(z["rig"]), float(z["length"]), float(z["estimator_s"]), path,
        z["support"], int(z["origin"]), float(z["rest_end"]),
    )



# -- the chain -----------------------------------------------------------------------------
def analysis(d: Deformations):
    """analytics.analyze on the deformation record the way ``shm analyze`` runs it
    (shm_service.processing.analysis): the estimator's support displacement as the measured input, windows
    aligned in data time, the warm-up after the rest phase skipped, the rig's FE damage signatures."""
    from shm_service.processing.analysis import DEFAULT_WARMUP_S

    t0 = time.perf_counter()
    sig = damage_signatures(parse_rig(d.rig_json), d.stations, gamma=d.b.shape[1])
    res = analyze(d.times, d.b, d.curvature_shapes, d.stations, temperature=d.temperature,
                  bearing=d.support if d.support is not None else d.bearing, expected_hz=d.expected_hz, beam_length=d.beam_length,
                  signatures=sig, time_origin_ns=d.origin_ns,
                  not_before_s=None if d.rest_end_s is None else d.rest_end_s + DEFAULT_WARMUP_S)
    return res, time.perf_counter() - t0


# -- the peer: pyOMA-2 SSI-cov on the raw accelerations --------------------------------------
def ensure_peer() -> bool:
    """Import pyoma2, installing pyOMA-2 with pip into this interpreter if it is missing."""
    try:
        import pyoma2  # noqa: F401

        return True
    except ImportError:
        pass
    _log(f"  installing {PEER_PACKAGE} (benchmark only) with: {sys.executable} -m pip install {PEER_PACKAGE}")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", PEER_PACKAGE], capture_output=True, text=True)
    if r.returncode != 0:
        _log(f"  could not install {PEER_PACKAGE}: {r.stderr.strip().splitlines()[-1:]}; install it by hand to get the peer column")
        return False
    try:
        import pyoma2  # noqa: F401

        return True
    except ImportError:
        return False


def peer_oma(path: Path, select_hz: list[float], *, decimate_to: float = 25.0) -> tuple[np.ndarray, np.ndarray, float]:
    """Frequencies (Hz) and damping ratios of the modes nearest ``select_hz`` by pyOMA-2's
    covariance-driven SSI on the y accelerations of every IMU, decimated to ~``decimate_to`` Hz.
    Returns (Fn, Xi, wall time s of the identification, reading excluded)."""
    import logging

    from scipy.signal import decimate

    from shm_service.recording import read_recording

    logging.getLogger("pyoma2").setLevel(logging.WARNING)
    rec = read_recording(path)
    chans = [c for _, c in sorted(rec.channels.items()) if c.kind == "imu"]
    n = min(len(c) for c in chans)
    acc = np.column_stack([c.values[:n, 1] for c in chans])
    fs = 1e9 / float(np.median(np.diff(chans[0].log_time_ns[:1000])))
    q = max(1, int(round(fs / decimate_to)))
    from pyoma2.algorithms import SSI
    from pyoma2.setup import SingleSetup

    t0 = time.perf_counter()
    x = decimate(acc, q, axis=0, zero_phase=True) if q > 1 else acc
    setup = SingleSetup(x, fs=fs / q)
    ssi = SSI(name="SSIcov", method="cov", br=80, ordmax=60)
    setup.add_algorithms(ssi)
    import contextlib
    import io

    with contextlib.redirect_stderr(io.StringIO()):  # progress bars
        setup.run_by_name("SSIcov")
        fn = xi = np.zeros(0)
        for order in ("find_min", 60, 40):  # the minimum stable order, else fixed orders
            try:
                ssi.mpe(sel_freq=list(select_hz), order_in=order)
                fn, xi = np.asarray(ssi.result.Fn, dtype=float).ravel(), np.asarray(ssi.result.Xi, dtype=float).ravel()
            except (ValueError, IndexError, TypeError):
                continue
            if fn.size == len(select_hz) and np.all(np.isfinite(fn)):
                break
    return fn, xi, time.perf_counter() - t0


# -- bars ----------------------------------------------------------------------------------
def _pct(a, b) -> str:
    return "   -   " if a is None or b is None else f"{100 * (a / b - 1):+7.3f}"


def modal_table(title: str, d: Deformations, res, dt: float, peer, *, damping: bool) -> list[str]:
    exact = json.loads(d.truth["eigenfrequencies_hz"])
    zeta = json.loads(d.truth["modal_damping_ratios"])
    rows = [f"\n[{title}]  estimator {d.estimator_s:.0f} s (when it ran; cached since), analytics {dt:.1f} s"
            + (f", pyOMA-2 SSI-cov {peer[2]:.1f} s" if peer else ""),
            " mode   exact Hz   ours Hz    err %   peer Hz    err %  |  ζ sim   ζ ours  err %   ζ peer  err %"]
    worst = {"f": 0.0, "z": 0.0}
    for m in res.modes:
        k = m.mode - 1
        f, z = m.frequency_hz, m.damping_ratio
        pf = pz = None
        if peer and k < peer[0].size and np.isfinite(peer[0][k]):
            pf, pz = float(peer[0][k]), float(peer[1][k])
        rows.append(f"  {m.mode:3d}  {exact[k]:9.5f}  {f or float('nan'):9.5f}  {_pct(f, exact[k])}  {pf or float('nan'):9.5f}  {_pct(pf, exact[k])}"
                    f"  | {zeta[k]:.4f}  {z or float('nan'):.4f} {_pct(z, zeta[k])[:-2]:>6}  {pz or float('nan'):.4f} {_pct(pz, zeta[k])[:-2]:>6}"
                    f"  {m.damping_method or ''}")
        if f:
            worst["f"] = max(worst["f"], abs(f / exact[k] - 1))
        if z and damping:
            worst["z"] = max(worst["z"], abs(z / zeta[k] - 1))
    rows.append(f"  worst |err|: frequency {100 * worst['f']:.3f} %" + (f", damping {100 * worst['z']:.1f} %" if damping else ""))
    return rows


def damage_row(name: str, res, damage_at: float | None, truth_third: str | None) -> tuple[str, bool]:
    flags = res.flags
    first = next((w for w in res.windows if w.flags and (damage_at is None or w.end_s > damage_at)), None)
    false_before = [f for f in flags if damage_at is not None and f["since_s"] is not None and f["since_s"] < damage_at]
    if damage_at is None:
        ok = not flags
        return f"  {name:34s} flags {len(flags):2d}  {'ok: none' if ok else 'FALSE ALARM ' + str([(f['kind'], f['mode']) for f in flags])}", ok
    if first is None:
        return f"  {name:34s} no flag after the damage", False
    delay = first.end_s - damage_at
    where = first.flags[0]
    last = next((w.location for w in reversed(res.windows) if w.location is not None), None)
    ok = delay <= 600 and where.get("third") == truth_third and not false_before
    kinds = sorted({f["kind"] + (str(f["mode"]) if f["mode"] else "") for f in first.flags})
    eta = where.get("eta_m")
    return (f"  {name:34s} first flag {delay:5.0f} s after damage ({','.join(kinds)}), located η={eta if eta is None else round(eta, 2)} m "
            f"{where.get('third')} ({where.get('damage_kind')}); at the end: η={None if last is None else round(last.eta_m, 2)} m "
            f"{None if last is None else last.third}; truth {truth_third}{'' if ok else '  <-- FAILS'}"), ok


def _seeds(args: list[str], flag: str, default: list[int]) -> list[int]:
    """The comma-separated seeds after ``flag`` in ``args``, else ``default``."""
    return [int(s) for s in args[args.index(flag) + 1].split(",")] if flag in args else default


def main(argv: list[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    quick = "--quick" in args
    peer_on = "--no-peer" not in args
    seeds = _seeds(args, "--seeds", [3])
    healthy_seeds = _seeds(args, "--healthy-seeds", [2] if quick else [2, 5, 6])
    dur = 900.0 if quick else 1800.0
    ideal = "--ideal" in args
    base = dict(duration=dur, ideal=ideal)
    _log(f"bench_analytics: {'quick ' if quick else ''}{dur:.0f} s runs, {'idealised' if ideal else 'realistic'} plant, cache {CACHE}")
    peer_ok = peer_on and ensure_peer()
    report: list[str] = []
    verdict: dict[str, bool] = {}

    # ambient: frequencies
    s = SimulationSettings(excitation="ambient", seed=1, **base)
    d = deformations(s)
    res, dt = analysis(d)
    sel = [f for g in d.expected_hz for f in g]
    peer = peer_oma(d.path, sel) if peer_ok else None
    report += modal_table(f"ambient {dur:.0f} s, seed 1: eigenfrequencies (random decrement damping)", d, res, dt, peer, damping=False)
    exact = json.loads(d.truth["eigenfrequencies_hz"])
    errs = {m.mode: abs(m.frequency_hz / exact[m.mode - 1] - 1) for m in res.modes if m.frequency_hz}
    verdict["frequencies (3-5 < 0.2 %, 1|2 < 0.5 %)"] = all(errs.get(k, 1) < 2e-3 for k in (3, 4, 5)) and min(errs.get(1, 1), errs.get(2, 1)) < 5e-3
    verdict["healthy ambient: no flag"] = not res.flags

    # decay: damping
    s = SimulationSettings(excitation="decay", seed=1, **base)
    d = deformations(s)
    res, dt = analysis(d)
    peer = peer_oma(d.path, sel) if peer_ok else None
    report += modal_table(f"decay {dur:.0f} s, seed 1: damping from the free decays", d, res, dt, peer, damping=True)
    zeta = json.loads(d.truth["modal_damping_ratios"])
    verdict["damping within 20 %"] = all(m.damping_ratio is not None and abs(m.damping_ratio / zeta[m.mode - 1] - 1) < 0.2 for m in res.modes)

    if not ideal and not quick:  # information: what bearing friction does to the same runs
        for excitation in ("ambient", "decay"):
            s = SimulationSettings(excitation=excitation, seed=1, plant={"friction_torque": STUDY_FRICTION}, **base)
            d = deformations(s)
            res, dt = analysis(d)
            report += modal_table(f"{excitation} {dur:.0f} s, seed 1, bearing friction {STUDY_FRICTION} N·m (information, not a bar)",
                                  d, res, dt, None, damping=excitation == "decay")

    # damage and healthy ±10 K. The damage appears after the baseline is learnt (windows from the
    # rest phase's end + warm-up, 180 s, for baseline_s = 480 s: armed at 660 s); a damage at
    # 600 s would be learnt into the baseline.
    report.append(f"\n[damage at {DAMAGE_AT:.0f} s in ambient runs with ±10 K, and healthy ±10 K runs]")
    cases = [(f"healthy ±10 K seed {sd}", dict(seed=sd), None, None) for sd in healthy_seeds]
    for sd in seeds:
        cases += [(f"mass 0.126 kg @ 4.0 m, seed {sd}", dict(seed=sd, damage=("mass:0.126@4.0",), damage_at=DAMAGE_AT), DAMAGE_AT, "lower"),
                  (f"EI×0.8 @ 1.0-1.2 m, seed {sd}", dict(seed=sd, damage=("stiffness:0.8@1.0-1.2",), damage_at=DAMAGE_AT), DAMAGE_AT,
                   "upper")]
    for name, kw, at, third in cases:
        # --quick: the damage runs keep the 10 minutes after the damage that the bar allows
        s = SimulationSettings(excitation="ambient", temperature_swing=20.0, **dict(base, duration=max(dur, DAMAGE_AT + 600.0) if at else dur),
                               **kw)
        d = deformations(s)
        res, dt = analysis(d)
        row, ok = damage_row(name, res, at, third)
        report.append(row)
        verdict[name] = ok
    _log("\n".join(report))
    _log("\nbars: " + "; ".join(f"{k}: {'ok' if v else 'FAIL'}" for k, v in verdict.items()))


if __name__ == "__main__":
    main()
