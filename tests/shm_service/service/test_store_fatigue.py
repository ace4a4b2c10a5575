"""The fatigue rows: a window's document round trip, a replayed window kept, a
reprocessed one replaced, the period and limit of a query, the document of a period."""

from __future__ import annotations

import sqlite3

import pytest

from contract import HotSpotLoadsDocument, LoadsWindowDocument, StationLoadsDocument
from shm_service.service.storage._fatigue import FatigueRepository, fatigue_document


def _window(start: float, consumed: float, rms: float = 1e-5, span: float = 4e-5) -> LoadsWindowDocument:
    spot = HotSpotLoadsDocument(name="weld", position_m=0.15, curve="EN1993-1-9:71", del_pa={"3": 2e7, "5": 1.8e7}, n_eq=10.0,
                                max_range_pa=5e7, damage_increment=1e-9, consumed=consumed, rate_per_year=3e-3,
                                rate_band_per_year=[2e-3, 4e-3], remaining_years=300.0, remaining_band_years=[250.0, None],
                                verdict="finite", design_life_years=20.0, del_band_pa={"3": [1.9e7, 2.1e7], "5": [1.7e7, 1.9e7]},
                                damage_band=[0.8e-9, 1.2e-9], band_method="modal truncation seen at the strain gauges (g1)")
    return LoadsWindowDocument(start_s=start, duration_s=10.0, temperature_c=None, hot_spots=[spot],
                               stations=[StationLoadsDocument(position_m=0.0, strain_rms=rms, strain_range_max=span,
                                                              stress_range_max_pa=span * 2.1e11)])


@pytest.fixture(params=["sqlite", "postgres"])
def conn(request):
    """A connection to the fatigue tables: SQLite's, or PostgreSQL's as its schema migrations make them."""
    if request.param == "sqlite":
        c = sqlite3.connect(":memory:")
        FatigueRepository.create_schema(c)
        FatigueRepository.create_schema(c)  # idempotent
    else:
        from shm_service.service import Storage
        from shm_service.service.storage.postgres._connection import PgConnection

        url = request.getfixturevalue("fresh_postgres_url")
        Storage(url).close()  # the schema
        c = PgConnection(url)
    yield c
    c.close()


def test_round_trip_replay_reprocess_and_period(conn):
    docs = [_window(1000.0 + 10 * k, 1e-9 * (k + 1), rms=1e-5 * (k + 1), span=4e-5 * (k + 1)) for k in range(5)]
    for d in docs:
        FatigueRepository.insert_window(conn, "mast", d)
    assert FatigueRepository.windows(conn, "mast") == docs
    FatigueRepository.insert_window(conn, "mast", _window(1000.0, 0.5))  # a replay of a stored window: kept as it was
    assert FatigueRepository.windows(conn, "mast")[0] == docs[0]
    FatigueRepository.insert_window(conn, "mast", _window(1000.0, 0.5), replace=True)  # reprocess replaces
    assert FatigueRepository.windows(conn, "mast")[0].hot_spots[0].consumed == 0.5
    assert FatigueRepository.windows(conn, "mast", 1010.0, 1030.0) == docs[1:3]
    assert FatigueRepository.count(conn, "mast", 1010.0) == 4 and FatigueRepository.count(conn, "other") == 0
    assert FatigueRepository.windows(conn, "mast", limit=2) == [FatigueRepository.windows(conn, "mast")[0], docs[1]]
    assert FatigueRepository.latest(conn, "mast") == docs[-1] and FatigueRepository.latest(conn, "mast", to_s=1010.0).start_s == 1000.0
    with pytest.raises(ValueError, match="limit"):
        FatigueRepository.windows(conn, "mast", limit=0)
    # the document of the period: the newest hot spots, the envelope (largest range, RMS over the windows' time)
    doc = fatigue_document("mast", docs[1:3], 4, docs[2])
    assert doc.hot_spots == docs[2].hot_spots and doc.truncated and doc.total == 4 and doc.design_life_years == 20.0
    (station,) = doc.envelope
    assert station.strain_range_max == pytest.approx(12e-5) and station.stress_range_max_pa == pytest.approx(12e-5 * 2.1e11)
    assert station.strain_rms == pytest.approx(((2e-5**2 + 3e-5**2) / 2) ** 0.5, rel=1e-12)
    empty = fatigue_document("mast", [], 0, None)
    assert empty.hot_spots == [] and empty.envelope == [] and not empty.truncated and empty.design_life_years is None
    # the rig's design life is the document's before any window was stored, and over the hot spots' own
    assert fatigue_document("mast", [], 0, None, design_life_years=25.0).design_life_years == 25.0
    assert fatigue_document("mast", docs[1:3], 4, docs[2], design_life_years=25.0).design_life_years == 25.0
