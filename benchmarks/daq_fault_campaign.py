"""The DAQ fault campaign: generated files with the faults field data has, through the
real commands, compared with the clean file sample by sample.

Each case writes an 8-channel, 200 Hz CSV of a three-mode response (``shm_service.formats.daq_faults``)
with random faults — blank cells, NaN, ±inf, 1e30, text, repeated and backwards times, a last row
cut short, a units row, decimal commas — then runs

- ``shm import`` (8 single-axis IMUs): every valid sample must be in the recording, bit for bit,
  and every faulted one counted (1e30 as ``implausible`` by the accelerometer limit);
- ``shm oma --json``: exit 0, the rejections counted, the modes of the clean file found with
  their shapes at MAC >= 0.99;
- the recording cut at half its size (``head -c``) through ``shm inspect`` and ``shm analyze``:
  both must say it is cut, neither may raise a traceback.

``python -m benchmarks.daq_fault_campaign [--cases N] [--seconds S]`` prints the figures
(``make bench`` runs it with the defaults).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

FS = 200.0
CHANNELS = 8


def _rig(path: Path) -> Path:
    rig = {"beam": {"length": 1.0, "width": 0.05, "thickness": 0.005, "youngs_modulus": 2.0e11, "density": 7850.0},
           "gravity": 9.81, "reflector_distance": 0.5, "support": "clamped",
           "sensors": [{"name": f"s{i}", "kind": "imu", "position": 0.1 * (i + 1)} for i in range(CHANNELS)]}
    path.write_text(json.dumps(rig))
    return path


def _map(path: Path) -> Path:
    lines = ['[clocks.daq]', 'column = "time"']
    for i in range(CHANNELS):
        lines += [f'[columns.ch{i}]', f'topic = "/imu/s{i}"', 'field = "accel"', 'index = 1']
    path.write_text("\n".join(lines) + "\n")
    return path


def _run(argv: list[str]) -> tuple[int, str, str, bool]:
    """(exit code, stdout, stderr, traceback?) of ``shm argv`` in this process."""
    from shm_service.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = int(exc.code or 0)
        except Exception:  # noqa: BLE001 - a traceback is what the campaign counts
            traceback.print_exc(file=err)
            return 1, out.getvalue(), err.getvalue(), True
    return code, out.getvalue(), err.getvalue(), False


def _mac(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(abs(a @ b) ** 2 / ((a @ a) * (b @ b)))


def _case(rng: np.random.Generator, clean: np.ndarray, tmp: Path, k: int) -> dict:
    from shm_service.formats.daq_faults import CELL_FAULTS, write_faulted_csv

    n = clean.shape[0]
    kinds = sorted(CELL_FAULTS)
    cells = {(int(rng.integers(n)), int(rng.integers(CHANNELS))): kinds[int(rng.integers(len(kinds)))]
             for _ in range(int(rng.integers(1, 12)))}
    faults = {"cells": cells,
              "repeated_times": tuple(int(x) for x in rng.integers(1, n, size=int(rng.integers(0, 3)))),
              "backwards_times": tuple(int(x) for x in rng.integers(3, n, size=int(rng.integers(0, 3)))),
              "cut_last_row": int(rng.integers(1, CHANNELS + 1)) if rng.random() < 0.5 else None,
              "units_row": bool(rng.random() < 0.3), "decimal_comma": bool(rng.random() < 0.3)}
    f = write_faulted_csv(tmp / f"case{k}.csv", clean, FS, **faults)
    expected_bad = np.zeros(clean.shape, dtype=bool)
    for i in f.rows:
        expected_bad[i] = True
    for (i, j) in f.cells:
        expected_bad[i, j] = True
    for j in f.truncated:
        expected_bad[n - 1, j] = True
    result = {"faulted_values": int(expected_bad.sum()), "tracebacks": 0}
    # shm import
    out = tmp / f"case{k}.mcap"
    code, text, err, tb = _run(["import", str(f.path), "--rig", str(tmp / "rig.json"), "--map", str(tmp / "map.toml"),
                                "--out", str(out), "--json"])
    result["tracebacks"] += tb
    result["import_exit"] = code
    if code == 0:
        from shm_service.recording import read_recording

        doc = json.loads(text)
        rec = read_recording(out)
        kept_ok = lost = 0
        for j in range(CHANNELS):
            channel = rec.channels.get(f"/imu/s{j}")
            valid = ~expected_bad[:, j]
            times = np.round(f.time[valid] * 1e9).astype(np.int64)
            if channel is not None and len(channel) == int(valid.sum()):
                same = np.array_equal(channel.values[:, 1], clean[valid, j]) and np.array_equal(
                    channel.log_time_ns - channel.log_time_ns[0], times - times[0])
                kept_ok += int(valid.sum()) if same else 0
                lost += 0 if same else int(valid.sum())
            else:
                lost += int(valid.sum()) - (0 if channel is None else min(len(channel), int(valid.sum())))
        result["valid_values"] = int((~expected_bad).sum())
        result["valid_kept_exactly"] = kept_ok
        result["rejected_counted"] = int(doc["rejected"])
        result["rejected_expected"] = int(expected_bad.sum())  # one column per topic: a value is a sample
    # shm oma
    code, text, err, tb = _run(["oma", str(f.path), "--fmax", "15", "--json"])
    result["tracebacks"] += tb
    result["oma_exit"] = code
    if code == 0:
        doc = json.loads(text)
        result["oma_rejected"] = doc["rejected_samples"]["total"]
        result["oma_modes"] = [(m["frequency_hz"], m["shape"]) for m in doc["modes"]]
    # the recording cut at half its size
    if out.exists():
        cut = tmp / f"case{k}-cut.mcap"
        cut.write_bytes(out.read_bytes()[: out.stat().st_size // 2])
        code, text, err, tb = _run(["inspect", str(cut), "--json"])
        result["tracebacks"] += tb
        result["inspect_says_cut"] = code == 0 and json.loads(text)["truncated"]
        code, text, err, tb = _run(["analyze", str(cut), "--json"])
        result["tracebacks"] += tb
        result["analyze_says_cut"] = ("cut off" in err) or (code == 0 and json.loads(text).get("truncated"))
    return result


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.daq_fault_campaign")
    parser.add_argument("--cases", type=int, default=12)
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--seed", type=int, default=26)
    args, _ = parser.parse_known_args(argv)
    from shm_service.formats.daq_faults import modal_response

    rng = np.random.default_rng(args.seed)
    clean = modal_response(int(args.seconds * FS), FS, CHANNELS)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        _rig(tmp / "rig.json")
        _map(tmp / "map.toml")
        from shm_service.formats.daq_faults import write_faulted_csv

        reference = write_faulted_csv(tmp / "clean.csv", clean, FS)
        code, text, err, _ = _run(["oma", str(reference.path), "--fmax", "15", "--json"])
        ref_modes = [(m["frequency_hz"], m["shape"]) for m in json.loads(text)["modes"]] if code == 0 else []
        results = [_case(rng, clean, tmp, k) for k in range(args.cases)]
    macs, freq_err, same_count = [], [], 0
    for r in results:
        modes = r.get("oma_modes", [])
        same_count += len(modes) == len(ref_modes)
        for (f, shape), (f0, shape0) in zip(modes, ref_modes):
            macs.append(_mac(shape, shape0))
            freq_err.append(abs(f / f0 - 1))
    summary = {
        "cases": len(results),
        "tracebacks": sum(r["tracebacks"] for r in results),
        "import_exit_0": sum(r["import_exit"] == 0 for r in results),
        "faulted_values": sum(r["faulted_values"] for r in results),
        "valid_values": sum(r.get("valid_values", 0) for r in results),
        "valid_kept_exactly": sum(r.get("valid_kept_exactly", 0) for r in results),
        "import_rejections_counted_exactly": sum(r.get("rejected_counted") == r.get("rejected_expected") for r in results),
        "oma_exit_0": sum(r["oma_exit"] == 0 for r in results),
        "oma_same_mode_count": same_count,
        "oma_min_mac": min(macs) if macs else None,
        "oma_max_frequency_error": max(freq_err) if freq_err else None,
        "cut_flagged_by_inspect": sum(bool(r.get("inspect_says_cut")) for r in results),
        "cut_flagged_by_analyze": sum(bool(r.get("analyze_says_cut")) for r in results),
        "wall_s": round(time.perf_counter() - started, 1),
    }
    print("DAQ fault campaign: " + json.dumps(summary))
    return summary


def failures(summary: dict) -> list[str]:
    """The campaign's bars the summary misses (empty: every bar met)."""
    n = summary["cases"]
    bars = {
        "no traceback": summary["tracebacks"] == 0,
        "every import exits 0": summary["import_exit_0"] == n,
        "every valid value kept exactly": summary["valid_kept_exactly"] == summary["valid_values"],
        "every faulted value counted": summary["import_rejections_counted_exactly"] == n,
        "every shm oma exits 0": summary["oma_exit_0"] == n,
        "the clean file's modes in every case": summary["oma_same_mode_count"] == n,
        "shapes at MAC >= 0.99": summary["oma_min_mac"] is not None and summary["oma_min_mac"] >= 0.99,
        "the cut recording flagged by shm inspect": summary["cut_flagged_by_inspect"] == n,
        "the cut recording flagged by shm analyze": summary["cut_flagged_by_analyze"] == n,
    }
    return [name for name, met in bars.items() if not met]


if __name__ == "__main__":
    import sys

    missed = failures(main())
    print("bars: " + ("all met" if not missed else "NOT met: " + "; ".join(missed)))
    sys.exit(1 if missed else 0)
