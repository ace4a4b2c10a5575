"""What ``Storage`` keeps besides a window's commit, on each engine (``storage_target``): pages
of trend rows and alarms by cursor, a reprocessed recording replacing its windows with its ledger
row, the baselines' lifecycle, the sources seen, a window's loads, the trend retention."""

from __future__ import annotations

import pytest

from contract import HotSpotLoadsDocument, LoadsWindowDocument, StationLoadsDocument, TrendRow
from shm_service.service import AlarmChange, Storage, WindowCommit


def _row(source: str, start: float, mode: int, f: float = 1.0) -> TrendRow:
    return TrendRow(source=source, window_start_s=start, window_end_s=start + 20.0, mode=mode, unit=mode, kind="ambient",
                    frequency_hz=f)


def _loads(start: float, consumed: float) -> LoadsWindowDocument:
    spot = HotSpotLoadsDocument(name="weld", position_m=0.15, curve="EN1993-1-9:71", del_pa={"3": 2e7}, n_eq=10.0,
                                max_range_pa=5e7, damage_increment=1e-9, consumed=consumed, verdict="finite")
    return LoadsWindowDocument(start_s=start, duration_s=10.0, temperature_c=None, hot_spots=[spot],
                               stations=[StationLoadsDocument(position_m=0.0, strain_rms=1e-5, strain_range_max=4e-5,
                                                              stress_range_max_pa=8.4e6)])


@pytest.fixture()
def st(storage_target):
    s = Storage(storage_target, notify_targets=[("webhook", "http://127.0.0.1:1/x")])
    yield s
    s.close()


def test_pages_of_trends_and_alarms_hold_every_row_once(st):
    for k in range(5):
        change = AlarmChange("raise", f"mode{k + 1}", "frequency", k + 1, "warning", 100.0 + k, 1.0, 0.5, f"alarm {k}")
        st.commit_window(WindowCommit("a", 20.0 * k, 20.0 * k + 20, [_row("a", 20.0 * k, 1), _row("a", 20.0 * k, 2)], None,
                                      None, [change]))
    keys, cursor, pages = [], None, 0
    while True:
        page = st.trends_page(source="a", limit=3, cursor=cursor)
        got = list(page.items)
        assert page.total == 10 and page.count == len(got)
        keys += [(r.window_start_s, r.mode) for r in got]
        pages += 1
        if not page.truncated:
            break
        cursor = page.next_cursor
    assert pages == 4 and keys == [(20.0 * k, m) for k in range(5) for m in (1, 2)]
    first = st.alarms_page(limit=2)
    ids = [a.id for a in first.items]
    rest = st.alarms_page(limit=10, cursor=first.next_cursor)
    ids += [a.id for a in rest.items]
    assert (first.total, first.truncated, rest.truncated) == (5, True, False) and ids == [5, 4, 3, 2, 1]
    assert [a.chart for a in st.alarms(state="active", source="a", limit=2)] == ["mode5", "mode4"]
    assert st.trends(from_s=20.0, to_s=60.0, mode=2) == [_row("a", 20.0, 2), _row("a", 40.0, 2)]


def test_a_reprocessed_recording_replaces_its_windows_and_is_done_once(st):
    st.commit_window(WindowCommit("a", 0.0, 20.0, [_row("a", 0.0, 1, f=1.0)], None, None, loads=_loads(0.0, 0.1)))
    assert st.reprocessed(["k1", "k2"]) == set()
    for f in (2.0, 3.0):  # a file reprocessed twice (--force): its windows replaced, not added
        st.commit_reprocessed(key="k1", path="/r/a.mcap", source="a", content_sha256="00", configuration="{}", windows=2,
                              start_s=0.0, end_s=40.0, rows=[_row("a", 0.0, 1, f=f), _row("a", 20.0, 1, f=f)],
                              loads=[_loads(0.0, f)])
    assert st.reprocessed(["k1", "k2"]) == {"k1"}
    assert [(r.window_start_s, r.frequency_hz) for r in st.trends(source="a")] == [(0.0, 3.0), (20.0, 3.0)]
    windows, total, latest = st.fatigue_windows("a")
    assert total == 1 and latest == windows[0] and windows[0].hot_spots[0].consumed == 3.0
    with pytest.raises(ValueError, match="source 'b' for source 'a'"):
        st.commit_reprocessed(key="k2", path="/r/b.mcap", source="a", content_sha256="00", configuration="{}", windows=1,
                              start_s=0.0, end_s=20.0, rows=[_row("b", 0.0, 1)])
    assert st.count("trends") == 2


def test_baselines_sources_and_trend_retention(st):
    assert st.request_baseline("a") == 1
    st.commit_window(WindowCommit("a", 0.0, 20.0, [], {"m": 1}, {"cal": 1}, baseline={"start_s": 0.0, "end_s": 20.0, "x": 1}))
    assert [(b["id"], b["state"], b["data"]) for b in st.baselines("a")] == [(1, "active", {"start_s": 0.0, "end_s": 20.0, "x": 1})]
    assert st.store_baseline("a", {"start_s": 5.0, "end_s": 9.0, "x": 2}) == 2
    assert [(b["id"], b["state"]) for b in st.baselines()] == [(2, "active"), (1, "superseded")]
    assert st.active_baseline("a") == {"start_s": 5.0, "end_s": 9.0, "x": 2}
    assert st.load_state("a") == {"last_window_start_s": 0.0, "data_time_s": 20.0, "monitor": None, "calibration": {"cal": 1}}
    st.save_calibration("a", {"cal": 2})
    assert st.load_state("a")["calibration"] == {"cal": 2}
    st.touch_sources([("a", "sim", "seed 1"), ("b", "ingest", ""), ("a", "sim", "seed 9")], 1000.0)  # a twice: the last
    st.touch_source("a", "sim", "seed 2", 1005.0)
    sources = st._read(lambda db: [tuple(r) for r in db.execute(
        "SELECT id, kind, detail, first_seen_s, last_seen_s FROM sources ORDER BY id").fetchall()])
    assert sources == [("a", "sim", "seed 2", 1000.0, 1005.0), ("b", "ingest", "", 1000.0, 1000.0)]
    # three days of windows of "a", one of "b": rows more than a day before their source's newest go
    for day in range(3):
        st.commit_window(WindowCommit("a", 86400.0 * day, 0.0, [_row("a", 86400.0 * day, 1)], None, None))
    st.commit_window(WindowCommit("b", 0.0, 0.0, [_row("b", 0.0, 1)], None, None))
    assert st.delete_trends_older_than(86400.0 * 1.5) == 1
    assert [(r.source, r.window_start_s) for r in st.trends()] == [("b", 0.0), ("a", 86400.0), ("a", 172800.0)]
