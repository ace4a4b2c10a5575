"""Cost of the loads: the streaming rainflow count per structure-second, next to the
`rainflow` package (ASTM E1049 three-point, whole records) on the same signals.

A structure here is one hour at 200 Hz of a narrow-band strain signal at each of 4 hot spots (the
signal of a lightly damped beam's first modes plus noise), counted in 10 s windows the way the
engine counts (HotSpotFatigue: streaming count, window DEL, Miner damage on an EN 1993-1-9 curve).

With ``--accuracy RAW EST`` it measures the virtual sensor instead: RAW a virtual-rig recording with
its truth (``shm simulate --ideal --duration 300``), EST its estimate (``shm estimate RAW --out EST``);
per truth station the strain RMS error and the DEL errors (m = 3, 5) against the truth's curvature
(ε_true = −c κ_true), the band's half-width and whether the true DEL lies in the band ``shm loads``
gives on RAW (leave-one-gauge-out: the estimator run again on RAW without each gauge, EST's model;
``--in-sample``: EST's in-sample residuals instead, as ``shm loads EST`` gives them).

With ``--replay RECORDING RIG`` it measures what the loads add to the service: the recording
replayed through ``shm serve``'s pipeline (in process, ``--speed max``) with RIG's hot spots and
again with a copy of RIG without them, the CPU time of each (the acceptance: at most 10 % more).

Without options it also checks the counting's acceptance items: the ASTM E1049 example through
``shm loads`` on a one-column CSV, and a 30-minute record counted whole and in 1 s batches.

Run: PYTHONPATH=. .venv/bin/python benchmarks/bench_loads.py [--quick] [--accuracy RAW EST] [--replay RECORDING RIG]
"""

from __future__ import annotations

import json
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


def accuracy(raw_path: str, est_path: str) -> None:
    """Virtual strain and DELs at the truth stations against the truth (see the module docstring)."""
    from analytics import signal_loads, virtual_strain
    from shm_service.processing.estimation import deformation_record, truth_from_recording
    from shm_service.commands.loads import loads_of_recording
    from shm_service.recording import read_recording

    raw, est = read_recording(raw_path), read_recording(est_path)
    record = deformation_record(est)
    stations = tuple(raw.rig.truth_stations)
    # the estimator's model as EST was made (its metadata), for the band's re-estimates without each gauge
    selection = json.loads(est.metadata["estimator"]["selection"])
    model_args = {"peripheral": selection["peripheral"], "modes": int(est.metadata["estimator"]["modes"]),
                  "imus": tuple(selection["imus"]), "tofs": tuple(selection["tofs"]), "gauges": tuple(selection["gauges"])}
    doc = loads_of_recording(raw, record=record, model_args=model_args, stations=stations, curve=None, exponents=(3.0, 5.0),
                             n_eq=None, half_cycles="half", start_s=None, leave_one_out="--in-sample" not in sys.argv)
    truth = truth_from_recording(raw)
    keep = record.times >= (record.rest_end_s or 0.0)
    idx = np.searchsorted(truth.t, record.times[keep])
    c = raw.rig.beam.fibre_distance(np.asarray(stations))
    true = -truth.curvature[idx] * c
    virtual = virtual_strain(record.b[keep], record.units.curvature(np.asarray(stations)), c)
    print(f"accuracy of the virtual strain: {est_path} against the truth of {raw_path}, {doc['duration_s']:.1f} s from {doc['start_s']:.1f} s")
    print(f"  band: {doc['band_method']}")
    for g in doc["gauges"]:
        print(f"  gauge {g['name']} at {g['position_m']:g} m ({'out of sample' if g['out_of_sample'] else 'in sample'}): "
              f"half-width {100 * g['half_width']:.2f} %")
    print(f"  {'η [m]':>6} {'RMS err %':>10} {'DEL3 err %':>11} {'DEL5 err %':>11} {'band ±%':>8}  true DEL in band (m=3, 5)")
    inside = [0, 0]
    for j, station in enumerate(doc["stations"]):
        ref = signal_loads(true[:, j], n_eq=doc["duration_s"]).dels
        rms = np.sqrt(np.mean((virtual[:, j] - true[:, j]) ** 2) / np.mean(true[:, j] ** 2))
        errs, ok = [], []
        for k, (entry, (_m, _n, dt)) in enumerate(zip(station["del"], ref)):
            errs.append(100 * (entry["strain_range"] / dt - 1))
            ok.append(entry["band"] is not None and entry["band"][0] <= dt <= entry["band"][1])
            inside[k] += ok[-1]
        width = station["band_half_width"]
        print(f"  {station['position_m']:6.2f} {100 * rms:10.2f} {errs[0]:11.2f} {errs[1]:11.2f} "
              f"{'-' if width is None else f'{100 * width:.2f}':>8}  {ok}")
    print(f"  true DEL inside the band at {inside[0]} (m=3) and {inside[1]} (m=5) of {len(stations)} stations")


def counting_acceptance() -> None:
    """The ASTM E1049-85 example through ``shm loads`` (a one-column CSV) and a 30-minute record
    counted whole and in 1 s batches (the loads' acceptance)."""
    import contextlib
    import io
    import json
    import tempfile
    from pathlib import Path

    from shm_service.cli import main as shm

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "astm.csv"
        path.write_text("strain\n" + "\n".join(str(v) for v in (-2, 1, -3, 5, -1, 3, -4, 4, -2)) + "\n")
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = shm(["loads", str(path), "--fs", "1", "--json"])
        doc = json.loads(out.getvalue())
    pairs = doc["channels"][0]["cycles_by_range"]
    expected = [[3.0, 0.5], [4.0, 1.5], [6.0, 0.5], [8.0, 1.0], [9.0, 0.5]]
    print(f"ASTM E1049-85 example through `shm loads` (one-column CSV, exit {code}): cycles_by_range {pairs} "
          f"{'= the standard' if pairs == expected else '!= the standard ' + str(expected)}")
    x = _signal(1800.0, 99)
    detail = FatigueDetail(sn_curve("EN1993-1-9:71"), gamma_mf=1.35)
    whole = detail.damage(rainflow_cycles(x))
    spot = HotSpotFatigue(detail)
    step = int(FS)
    for k in range(0, x.size, step):
        spot.push(x[k:k + step], 1.0)
    print(f"30-minute record at {FS:.0f} Hz, counted whole and in 1 s batches: D = {whole:.6e} and {spot.consumed:.6e}, "
          f"relative difference {abs(spot.consumed / whole - 1):.1e}")


def replay_overhead(recording: str, rig_path: str) -> None:
    """CPU time of a replay through the service's pipeline with and without the rig's hot spots."""
    import json
    import resource
    import subprocess
    import tempfile
    from pathlib import Path

    rig = json.loads(Path(rig_path).read_text())
    if not rig.get("hot_spots"):
        raise SystemExit(f"{rig_path} names no hot spots: nothing to compare")
    script = (
        "import sys, time; from shm_service.service import MonitoringService, load_settings;"
        "s = load_settings(None, {'db': sys.argv[1], 'source': {'spec': 'replay:' + sys.argv[2], 'rig': sys.argv[3], 'speed': 'max'},"
        " 'archive': {'enabled': False}, 'dashboard': {'enabled': False}, 'server': {'port': 0},"
        " 'estimator': {'peripheral': 'gyro', 'modes': 4, 'imus': 4, 'tofs': 0, 'gauges': 4}});"
        "svc = MonitoringService(s, environ={}); svc.start(); svc.wait(); st = svc.status(); svc.stop(drain_s=0);"
        "print(st.pipeline.windows_committed, st.service.pipeline_errors)")
    with tempfile.TemporaryDirectory() as tmp:
        bare = dict(rig, hot_spots=[], fatigue=None)
        plain = Path(tmp) / "rig_without_hot_spots.json"
        plain.write_text(json.dumps(bare))
        cpu = {}
        for label, path in (("loads off", str(plain)), ("loads on", rig_path), ("loads off", str(plain)), ("loads on", rig_path)):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            done = subprocess.run([sys.executable, "-c", script, str(Path(tmp) / f"{label}-{len(cpu)}.sqlite"), recording, path],
                                  capture_output=True, text=True, check=True)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            used = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            cpu.setdefault(label, []).append(used)
            print(f"  {label}: {used:7.1f} s CPU, windows committed and pipeline errors: {done.stdout.strip()}")
    off, on = min(cpu["loads off"]), min(cpu["loads on"])
    print(f"replay of {recording} (--speed max, in-process service): loads add {100 * (on / off - 1):+.1f} % CPU "
          f"(best of two each: {on:.1f} s with, {off:.1f} s without)")


def main(argv: list[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    if "--accuracy" in args:
        i = args.index("--accuracy")
        accuracy(args[i + 1], args[i + 2])
        return
    if "--replay" in args:
        i = args.index("--replay")
        replay_overhead(args[i + 1], args[i + 2])
        return
    counting_acceptance()
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
