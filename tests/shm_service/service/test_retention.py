"""The data directory and retention: where a service's files go, the recording size and age
limits, the trend age limit, and the worker applying them on a running service."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from contract import TrendRow
from shm_service.service import RetentionSettings, SettingsError, Storage, WindowCommit, load_settings
from shm_service.service.storage._archive_names import parse_archive_name
from shm_service.service.storage._retention import RecordingFile, RetentionWorker, list_recordings, plan_recording_retention

HOUR = 3600.0
DAY = 86400.0
T0 = 1_767_225_600.0  # 2026-01-01T00:00:00Z


def test_every_file_of_a_service_goes_under_one_data_directory(tmp_path):
    s = load_settings(None)
    assert (s.data_dir, s.db, s.archive.directory) == ("var", "var/shm.sqlite", "var/recordings")
    s = load_settings(None, {"data_dir": str(tmp_path / "d")})
    assert s.db == str(tmp_path / "d" / "shm.sqlite") and s.archive.directory == str(tmp_path / "d" / "recordings")
    # --db elsewhere takes the recordings along (they used to land in ./var/recordings)
    s = load_settings(None, {"db": str(tmp_path / "x" / "a.sqlite")})
    assert s.data_dir == str(tmp_path / "x") and s.archive.directory == str(tmp_path / "x" / "recordings")
    # explicit paths win
    s = load_settings(None, {"data_dir": str(tmp_path / "d"), "archive": {"directory": str(tmp_path / "big")}})
    assert s.archive.directory == str(tmp_path / "big") and s.db == str(tmp_path / "d" / "shm.sqlite")
    with pytest.raises(SettingsError, match="recordings_max_gb"):
        load_settings(None, {"retention": {"recordings_max_gb": 0.1}, "archive": {"rotate_mb": 256}})
    with pytest.raises(SettingsError, match="trends_max_age_days"):
        load_settings(None, {"retention": {"trends_max_age_days": 0}})


def _name(source: str, start_s: float, n: int = 0) -> str:
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(start_s))
    return f"{source}-{stamp}-w20261201T120000{'-' + str(n) if n else ''}.mcap"


def test_archive_names_are_read_back():
    assert parse_archive_name(_name("sim", T0 + 90)) .start_s == T0 + 90
    assert parse_archive_name(_name("my-rig-2", T0, 3)).source == "my-rig-2"
    assert parse_archive_name("notes.mcap") is None and parse_archive_name("sim-x.mcap") is None


def _files(tmp: Path, spec) -> list[RecordingFile]:
    return [RecordingFile(tmp / _name(src, start), src, start, size) for src, start, size in spec]


def test_size_limit_deletes_the_oldest_first_and_keeps_the_current_file(tmp_path):
    files = _files(tmp_path, [("sim", T0 + i * HOUR, 100) for i in range(6)])
    doomed = plan_recording_retention(files, max_bytes=350, max_age_s=None)
    assert [f.start_s for f in doomed] == [T0, T0 + HOUR, T0 + 2 * HOUR]
    # the file being written is never deleted, even when it is the oldest (a clock jump)
    doomed = plan_recording_retention(files, max_bytes=350, max_age_s=None, keep=[files[0].path])
    assert [f.start_s for f in doomed] == [T0 + HOUR, T0 + 2 * HOUR, T0 + 3 * HOUR]
    # nothing to do within budget; the newest file stays even over budget
    assert plan_recording_retention(files, max_bytes=600, max_age_s=None) == []
    assert plan_recording_retention(files, max_bytes=1, max_age_s=None) == files[:5]


def test_age_limit_is_in_data_time_per_source(tmp_path):
    # sim: hourly files over 3 days; replay: old data (2020) in two files
    spec = [("sim", T0 + i * HOUR, 10) for i in range(72)] + [("replay", T0 - 6 * 365 * DAY + i * HOUR, 10) for i in range(2)]
    files = _files(tmp_path, spec)
    doomed = plan_recording_retention(files, max_bytes=1e9, max_age_s=DAY)
    newest = T0 + 71 * HOUR
    # a file goes when its data end (the next file's start) is more than a day before the newest file starts
    assert {f.source for f in doomed} == {"sim"}
    assert all(f.start_s + HOUR < newest - DAY for f in doomed)
    assert len(doomed) == 46  # files 0..45 end (hour i + 1) before hour 47 = newest - 24 h
    with pytest.raises(ValueError, match="max_bytes"):
        plan_recording_retention(files, max_bytes=0, max_age_s=None)
    with pytest.raises(ValueError, match="max_age_s"):
        plan_recording_retention(files, max_bytes=1, max_age_s=-1)


def _trend_commit(source: str, start_s: float) -> WindowCommit:
    row = TrendRow(source=source, window_start_s=start_s, window_end_s=start_s + 60, mode=2, unit=1, kind="ambient",
                   frequency_hz=0.86, damping_ratio=0.005, amplitude=1e-3, confidence=0.9, temperature_c=20.0,
                   curvature_index=0.1, score_sigma=0.2, level="ok")
    return WindowCommit(source, start_s, start_s + 60, [row], None, None)


def test_trend_rows_older_than_the_limit_before_their_sources_newest_window_go(tmp_path):
    st = Storage(tmp_path / "s.sqlite")
    for day in range(10):
        st.commit_window(_trend_commit("sim", T0 + day * DAY))
    st.commit_window(_trend_commit("old-replay", T0 - 365 * DAY))
    assert st.delete_trends_older_than(3 * DAY) == 6  # days 0..5 are more than 3 days before day 9
    kept = [r.window_start_s for r in st.trends(source="sim")]
    assert kept == [T0 + d * DAY for d in range(6, 10)]
    assert st.count("trends") == 5  # the replay's single row is its own newest
    with pytest.raises(ValueError, match="age_s"):
        st.delete_trends_older_than(0)
    st.close()


def test_worker_deletes_real_files_and_rows_and_counts(tmp_path):
    rec = tmp_path / "recordings"
    rec.mkdir()
    for i in range(5):
        (rec / _name("sim", T0 + i * HOUR)).write_bytes(b"x" * 1000)
    (rec / "notes.txt").write_text("not the archive's")
    (rec / "someone-elses.mcap").write_bytes(b"y" * 10_000)
    st = Storage(tmp_path / "s.sqlite")
    for day in range(3):
        st.commit_window(_trend_commit("sim", T0 + day * DAY))
    settings = RetentionSettings(recordings_max_gb=2.5e-6, recordings_max_age_days=None, trends_max_age_days=1.0, interval_s=3600)
    current = rec / _name("sim", T0 + 4 * HOUR)
    worker = RetentionWorker(settings, storage=st, directory=rec, current=lambda: str(current))
    assert worker.run_once() == {"files": 3, "bytes": 3000, "trend_rows": 1}
    assert sorted(p.name for p in rec.iterdir()) == sorted([_name("sim", T0 + 3 * HOUR), current.name, "notes.txt",
                                                            "someone-elses.mcap"])
    assert [f.start_s for f in list_recordings(rec)] == [T0 + 3 * HOUR, T0 + 4 * HOUR]
    assert worker.status()["files_deleted"] == 3 and worker.status()["errors"] == 0
    st.close()
    assert worker.run_once()["trend_rows"] == 0 and worker.status()["errors"] == 1  # a closed database is logged, not raised


def test_a_running_service_applies_retention_to_its_data_directory(tmp_path):
    from svc_helpers import fast_overrides

    from shm_service.service import MonitoringService

    overrides = fast_overrides(tmp_path, **{"source.spec": "sim", "source.speed": "max", "sim.duration_s": 120.0,
                                            "sim.damage_at_s": None, "archive.rotate_s": 20.0,
                                            "retention.recordings_max_age_days": 40.0 / DAY,
                                            "retention.interval_s": 0.2})
    del overrides["db"], overrides["archive"]["directory"]  # both derived from data_dir
    overrides["data_dir"] = str(tmp_path / "data")
    service = MonitoringService(load_settings(None, overrides), environ={})
    service.start()
    try:
        assert service.wait(300)
        runs = service.retention.runs
        deadline = time.monotonic() + 10
        while service.retention.runs < runs + 2 and time.monotonic() < deadline:  # a pass after the last file
            time.sleep(0.05)
    finally:
        service.stop(drain_s=0)
    data = tmp_path / "data"
    assert sorted(p.name for p in data.iterdir() if not p.name.startswith("shm.sqlite-")) == ["recordings", "shm.sqlite"]
    left = list_recordings(data / "recordings")
    assert service.retention.files_deleted >= 2 and service.retention.errors == 0
    # what is left spans at most the age limit plus one file
    assert left[-1].start_s - left[0].start_s <= 40.0 + 20.0 + 1.0


def test_a_recording_file_holds_at_most_rotate_s_of_data_however_much_one_write_brings(tmp_path):
    from shm_service.rig_layouts import default_rig
    from shm_service.service import ArchiveSettings
    from shm_service.service.stages._archive import Archive

    archive = Archive(ArchiveSettings(directory=str(tmp_path), rotate_s=20.0), default_rig("benchmark"), "sim", None)
    t0 = int(T0 * 1e9)
    stamps = [t0 + k * 5 * 10**9 for k in range(11)]  # 0, 5, ..., 50 s: one call
    archive.write_estimates(stamps, [b"{}"] * len(stamps))
    archive.close()
    starts = [f.start_s for f in list_recordings(tmp_path)]
    assert starts == [T0, T0 + 20.0, T0 + 40.0] and archive.messages == 11 and archive.errors == 0
