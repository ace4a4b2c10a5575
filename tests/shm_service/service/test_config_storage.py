"""Configuration (typed, closed, documented) and storage (migrations, idempotent windows,
atomic outbox)."""

from __future__ import annotations

import sqlite3
import tomllib

import pytest

from contract import TrendRow
from shm_service.service import (
    SCHEMA_VERSION,
    AlarmChange,
    ServiceSettings,
    SettingsError,
    Storage,
    WindowCommit,
    load_settings,
    render_toml,
    resolve_token,
)


def test_rendered_defaults_parse_back_to_the_defaults():
    text = render_toml()
    assert ServiceSettings.model_validate(tomllib.loads(text)) == ServiceSettings()
    assert "# SQLite database" in text and "[analytics]" in text


def test_the_sections_are_the_stages_settings_with_one_default_each():
    from shm_service.service.stages._archive import ArchiveSettings
    from shm_service.service.stages._checks import CheckSettings
    from shm_service.service.stages._commit import CommitSettings
    from shm_service.service.stages._estimate import EstimateSettings
    from shm_service.service.stages._merge import MergeSettings

    s = load_settings(overrides={"source": {"silent_after_s": 3.0, "lateness_s": 0.5}, "archive": {"estimate_decimation": 2}})
    assert isinstance(s.source, MergeSettings) and isinstance(s.source, CheckSettings)
    assert isinstance(s.estimator, EstimateSettings) and isinstance(s.archive, ArchiveSettings)
    assert (s.source.silent_after_s, s.source.lateness_s, s.archive.estimate_decimation) == (3.0, 0.5, 2)
    # a stage built without settings has the defaults the configuration's users have
    assert (CheckSettings().silent_after_s, MergeSettings().lateness_s, ArchiveSettings().estimate_decimation) == (2.0, 1.0, 4)
    assert CommitSettings().retry_s == ServiceSettings().storage_retry_s == 10.0


def test_config_is_closed_and_flags_override(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('db = "a.sqlite"\n[server]\nport = 9000\n')
    s = load_settings(cfg, {"server": {"port": 9001}})
    assert s.db == "a.sqlite" and s.server.port == 9001
    cfg.write_text("[server]\nportt = 1\n")
    with pytest.raises(SettingsError, match="server.portt"):
        load_settings(cfg)
    with pytest.raises(SettingsError, match="speed"):
        load_settings(None, {"source": {"speed": "fast"}})
    with pytest.raises(SettingsError, match="source"):
        load_settings(None, {"source": {"spec": "replay:"}})
    with pytest.raises(SettingsError, match="host"):
        load_settings(None, {"server": {"host": "example.org"}})


def test_token_from_environment_or_file(tmp_path):
    s = load_settings(None)
    assert resolve_token(s, {}) is None
    assert resolve_token(s, {"SHM_TOKEN": "secret-123"}) == "secret-123"
    f = tmp_path / "token"
    f.write_text("file-token-1\n")
    s = load_settings(None, {"server": {"token_file": str(f)}})
    assert resolve_token(s, {"SHM_TOKEN": "other-token"}) == "file-token-1"
    f.write_text("short\n")
    with pytest.raises(SettingsError, match="8 characters"):
        resolve_token(s, {})


def _row(start, mode, f=1.0):
    return TrendRow(source="src", window_start_s=start, window_end_s=start + 20, mode=mode, unit=mode, kind="ambient",
                    frequency_hz=f, damping_ratio=0.01, amplitude=1e-3, confidence=0.9, temperature_c=20.0,
                    curvature_index=0.1, score_sigma=0.5, level="ok")


def test_migrations_and_idempotent_windows(storage_target):
    db = storage_target
    st = Storage(db, notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    # each engine its own numbering of migrations; SQLite's is the one exported
    assert st.schema_version == st.database.schema_latest == (SCHEMA_VERSION if db.endswith(".sqlite") else 3)
    raise_ = AlarmChange("raise", "mode2", "frequency", 2, "warning", 120.0, 3.1, 3.0, "m")
    commit = WindowCommit("src", 100.0, 120.0, [_row(100.0, 1), _row(100.0, 2)], {"monitor": None}, None, [raise_])
    st.commit_window(commit)
    st.commit_window(commit)  # a replay of the same window
    assert st.count("trends") == 2
    assert len(st.alarms()) == 1 and len(st.outbox()) == 1
    st.close()
    st = Storage(db)  # reopening does not migrate again
    assert st.schema_version == st.database.schema_latest and st.count("trends") == 2
    assert st.load_state("src")["last_window_start_s"] == 100.0
    assert st.trends() == [_row(100.0, 1), _row(100.0, 2)]  # what was stored is what is read, typed
    acked = st.acknowledge(1, "op")
    assert acked.acknowledged_by == "op" and acked.acknowledged and acked.acknowledged_at_s > 0
    assert st.acknowledge(1, "other").acknowledged_by == "op"
    assert st.acknowledge(99, "op") is None


def test_a_biaxial_beams_zeta_and_xi_mode_of_one_window_are_two_rows_and_pages_follow_the_key(storage_target):
    st = Storage(storage_target)
    rows = [_row(100.0, 1), _row(100.0, 1, 1.01).model_copy(update={"plane": "xi"}), _row(100.0, 2)]
    st.commit_window(WindowCommit("src", 100.0, 120.0, rows, {"monitor": None}, None, []))
    assert st.count("trends") == 3
    # the key's order: window start, source, mode, plane ("xi" < "zeta")
    assert [(r.mode, r.plane, r.frequency_hz) for r in st.trends()] == [(1, "xi", 1.01), (1, "zeta", 1.0), (2, "zeta", 1.0)]
    first = st.trends_page(limit=1)
    got = list(first.items)
    second = st.trends_page(limit=2, cursor=first.next_cursor)
    assert [(r.mode, r.plane) for r in got + list(second.items)] == [(1, "xi"), (1, "zeta"), (2, "zeta")]
    st.close()


def test_a_version_5_database_keeps_its_trends_in_the_zeta_plane(tmp_path):
    from shm_service.service.storage.sqlite._schema import _MIGRATIONS

    db = tmp_path / "v5.sqlite"
    con = sqlite3.connect(db)
    for script in _MIGRATIONS[:5]:
        con.executescript(script)
    con.execute("INSERT INTO trends (source, window_start_s, window_end_s, mode, unit, kind, frequency_hz, created_at) "
                "VALUES ('src', 100.0, 120.0, 1, 1, 'ambient', 1.5, 1.0)")
    con.execute("PRAGMA user_version = 5")
    con.commit()
    con.close()
    st = Storage(db)
    (row,) = st.trends()
    assert (row.mode, row.frequency_hz, row.plane) == (1, 1.5, "zeta")
    st.close()


def test_version_1_database_keeps_its_acknowledgements(tmp_path):
    """Schema 2 spells the acknowledgement time like the alarm's other times (acknowledged_at_s)."""
    from shm_service.service.storage.sqlite._schema import _MIGRATIONS

    db = tmp_path / "v1.sqlite"
    con = sqlite3.connect(db)
    con.executescript(_MIGRATIONS[0])
    con.execute("INSERT INTO alarms (source, chart, kind, mode, level, state, raised_at_s, acknowledged_at, acknowledged_by, "
                "message) VALUES ('src', 'mode2', 'frequency', 2, 'alarm', 'active', 10.0, 12.5, 'op', 'm')")
    for at in (10.0, 12.5):
        con.execute("INSERT INTO alarm_events (alarm_id, event, level, at_s, created_at) VALUES (1, ?, 'alarm', ?, ?)",
                    ("raised" if at == 10.0 else "acknowledged", at, at))
    con.execute("INSERT INTO outbox (event_id, channel, target, payload, status, next_attempt_at, created_at) "
                "VALUES (1, 'webhook', 'http://127.0.0.1:1/x', '{}', 'sent', 10.0, 10.0)")
    con.execute("PRAGMA user_version = 1")
    con.commit()
    con.close()
    st = Storage(db)
    assert st.schema_version == SCHEMA_VERSION == 6  # 3: event sequence numbers and UUIDs; 4: the ledger of shm reprocess; 5: fatigue rows; 6: the trends' plane
    assert st.fatigue_windows("src") == ([], 0, None)  # 5: the fatigue tables exist, empty
    (alarm,) = st.alarms()
    assert alarm.acknowledged_at_s == 12.5 and alarm.acknowledged_by == "op" and alarm.acknowledged and not alarm.stale
    # schema 3: the events got their per-alarm sequence numbers and distinct UUIDs, the outbox its alarm
    events = st.alarm_events()
    assert [e["seq"] for e in events] == [1, 2] and len({e["uuid"] for e in events}) == 2
    assert st.outbox()[0]["alarm_id"] == 1 and st.integrity_check() == "ok"


def test_a_failing_window_commit_leaves_nothing(storage_target):
    st = Storage(storage_target, notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    bad = AlarmChange("explode", "mode1", "frequency", 1, "alarm", 1.0, None, None, "m")
    with pytest.raises(ValueError):
        st.commit_window(WindowCommit("src", 0.0, 20.0, [_row(0.0, 1)], None, None,
                                      [AlarmChange("raise", "mode1", "frequency", 1, "alarm", 1.0, 6.0, 5.0, "m"), bad]))
    assert st.count("trends") == 0 and st.alarms() == [] and st.outbox() == []


def test_newer_schema_is_refused(tmp_path):
    db = tmp_path / "s.sqlite"
    Storage(db).close()
    con = sqlite3.connect(db)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.close()
    with pytest.raises(RuntimeError, match="newer"):
        Storage(db)
