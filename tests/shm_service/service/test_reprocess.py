"""shm reprocess and shm baseline learn on real dask.distributed clusters (a LocalCluster of
their own, and an existing one given by its scheduler address), against shm analyze."""

from __future__ import annotations

import json
import logging

import pytest

from shm_service.cli import main
from shm_service.service import Storage
from shm_service.virtual_rig import SimulationSettings, simulate


def _run(capsys, *args: str) -> tuple[int, dict]:
    code = main(list(args))
    return code, json.loads(capsys.readouterr().out)


def _close(a, b, rel: float) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and a == pytest.approx(b, rel=rel))


@pytest.mark.slow
def test_reprocess_is_analyze_per_file_idempotent_and_feeds_the_service_baseline(short_recording, tmp_path, capsys,
                                                                                 storage_target):
    from distributed import LocalCluster

    tiny = tmp_path / "tiny.mcap"  # shorter than one analysis window: still done
    simulate(SimulationSettings(duration=30.0, rest=10.0, excitation="ambient", seed=5), tiny)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\nthis is not a recording")
    db = storage_target  # a SQLite file or a PostgreSQL database: the same commands
    files = [str(short_recording), str(tiny), str(bad)]
    # the tests' short windows and warm-up (the recording is 150 s): one configuration for all
    config = tmp_path / "shm.toml"
    config.write_text("[analytics]\nwindow_s = 20.0\noverlap = 0.5\nbaseline_s = 40.0\nbaseline_min_windows = 3\n"
                      "[estimator]\ncalibration_s = 10.0\nwarmup_s = 5.0\n")

    code, doc = _run(capsys, "reprocess", *files, "--db", str(db), "--workers", "2", "--config", str(config), "--json")
    assert code == 1  # one file failed, the others are done
    by_path = {f["path"]: f for f in doc["files"]}
    assert [f["path"] for f in doc["files"]] == files and doc["wall_s"] > 0
    assert by_path[str(short_recording)]["status"] == "done" and by_path[str(short_recording)]["windows"] >= 3
    assert by_path[str(tiny)] == {"path": str(tiny), "status": "done", "windows": 0, "error": None}
    assert by_path[str(bad)]["status"] == "failed" and "bad.mcap" in by_path[str(bad)]["error"]

    # the rows are shm analyze's windows, at the recording's time
    assert main(["analyze", str(short_recording), "--config", str(config), "--json"]) == 0
    analysis = json.loads(capsys.readouterr().out)
    from shm_service.recording import read_recording

    offset = read_recording(short_recording, kinds=("imu",)).start_ns / 1e9
    storage = Storage(db)
    rows = storage.trends(source="short")
    assert len(rows) == sum(len(w["modes"]) for w in analysis["windows"]) > 0
    stored = {(round(r.window_start_s - offset, 6), r.mode): r for r in rows}
    for w in analysis["windows"]:
        for m in w["modes"]:
            r = stored[(round(w["start_s"], 6), m["mode"])]
            assert r.window_end_s - offset == pytest.approx(w["end_s"], abs=1e-6)
            # the same engine; a dask worker runs its BLAS on one thread, so sums may round differently
            assert (r.kind, r.unit) == (w["kind"], m["unit"])
            assert _close(r.frequency_hz, m["frequency_hz"], 1e-9) and _close(r.amplitude, m["amplitude"], 1e-6)
            assert r.confidence == pytest.approx(m["confidence"], abs=1e-4) and r.temperature_c == w["temperature_c"]
            assert _close(r.curvature_index, w["curvature_index"], 1e-6)
    assert storage.count("trends") == len(rows)  # the tiny file has no window

    # an existing cluster by its address: the same code; done files are skipped, --force redoes them
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=":0", silence_logs=logging.ERROR) as cluster:
        address = cluster.scheduler_address
        code, again = _run(capsys, "reprocess", *files[:2], "--db", str(db), "--scheduler", address, "--config", str(config),
                           "--json")
        assert code == 0 and [f["status"] for f in again["files"]] == ["skipped", "skipped"]
        code, forced = _run(capsys, "reprocess", files[0], "--db", str(db), "--scheduler", address, "--config", str(config),
                            "--force", "--json")
        assert code == 0 and forced["files"][0]["status"] == "done"
        assert Storage(db).count("trends") == len(rows)  # replaced, not added

        # a baseline from the healthy part (the damage appears at 90 s), stored for the service
        code, learnt = _run(capsys, "baseline", "learn", files[0], "--structure", "mast-01", "--db", str(db),
                            "--from", str(offset), "--to", str(offset + 90.0), "--scheduler", address, "--config",
                            str(config), "--json")
    assert code == 0 and learnt["structure"] == "mast-01" and learnt["trusted_windows"] >= 1
    assert learnt["end_s"] <= offset + 90.0 and len(learnt["modes"]) == 5
    active = Storage(db).active_baseline("mast-01")
    assert active is not None and [m["f_ref_hz"] for m in active["modes"]] == [m["frequency_hz"] for m in learnt["modes"]]

    from estimator import build_model
    from shm_service.service.stages._analysis import AnalysisStage

    model = build_model(read_recording(short_recording, kinds=()).rig)
    from shm_service.service import load_settings

    live = AnalysisStage(model, load_settings(config).engine_config(), None, None, "mast-01", baseline=active)  # as the service starts
    assert live.monitor.baseline is not None and not live.learning_baseline
    assert main(["baseline", "learn", files[0], "--structure", "x", "--db", str(db), "--from", "10", "--to", "5"]) == 2
