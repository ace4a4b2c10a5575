"""The fatigue rows of the service's database: per structure, analysis window and hot
spot the window's loads (DEL per Wöhler exponent, largest range, damage increment) and the hot
spot's life after it (consumed D, damage rate, remaining life, verdict); per window the strain
envelope along the beam.

Written by the window's commit in the same transaction as its trend rows and the engine state
(whose ``loads`` part holds the rainflow residue): after a SIGKILL the database holds a window's
rows exactly when it holds the residue and damage that include it, so a restart neither loses
nor double-counts a cycle. Rows of a window already stored are kept (a replay of the same period).

The repository is a class over a connection (the caller's transaction), as the other stores are.
"""

from __future__ import annotations

import json
import math
import sqlite3
from typing import Any

from contract import FatigueDocument, HotSpotLoadsDocument, LoadsWindowDocument, StationLoadsDocument

__all__ = ["FATIGUE_SCHEMA", "FatigueRepository", "fatigue_document"]

#: The tables (one migration of the database's schema: ``storage._storage._MIGRATIONS``).
FATIGUE_SCHEMA = """
    CREATE TABLE IF NOT EXISTS fatigue_windows (
        source TEXT NOT NULL,
        window_start_s REAL NOT NULL,
        duration_s REAL NOT NULL,
        temperature_c REAL,
        stations TEXT NOT NULL,
        created_at REAL NOT NULL,
        PRIMARY KEY (source, window_start_s)
    ) WITHOUT ROWID;
    CREATE TABLE IF NOT EXISTS fatigue_hot_spots (
        source TEXT NOT NULL,
        window_start_s REAL NOT NULL,
        hot_spot TEXT NOT NULL,
        position_m REAL NOT NULL,
        curve TEXT NOT NULL,
        del_pa TEXT NOT NULL,
        n_eq REAL NOT NULL,
        max_range_pa REAL,
        damage_increment REAL,
        consumed REAL,
        rate_per_year REAL,
        rate_band_per_year TEXT,
        remaining_years REAL,
        remaining_band_years TEXT,
        verdict TEXT NOT NULL,
        design_life_years REAL,
        del_band_pa TEXT,
        damage_band TEXT,
        band_method TEXT,
        PRIMARY KEY (source, window_start_s, hot_spot)
    ) WITHOUT ROWID
"""

_SPOT_COLUMNS = ("position_m", "curve", "del_pa", "n_eq", "max_range_pa", "damage_increment", "consumed", "rate_per_year",
                 "rate_band_per_year", "remaining_years", "remaining_band_years", "verdict", "design_life_years", "del_band_pa",
                 "damage_band", "band_method")
_JSON = frozenset({"del_pa", "rate_band_per_year", "remaining_band_years", "del_band_pa", "damage_band"})


def _conditions(source: str, from_s: float | None, to_s: float | None) -> tuple[str, list[Any]]:
    where: list[str] = ["source = ?"]
    args: list[Any] = [source]
    if from_s is not None:
        where.append("window_start_s >= ?")
        args.append(float(from_s))
    if to_s is not None:
        where.append("window_start_s < ?")
        args.append(float(to_s))
    return " AND ".join(where), args


class FatigueRepository:
    """The fatigue rows over a connection (the caller holds the transaction or the read lock)."""

    @staticmethod
    def create_schema(conn: sqlite3.Connection) -> None:
        """Create the tables when they are missing (``storage._storage`` runs the same text as a migration)."""
        for statement in (s.strip() for s in FATIGUE_SCHEMA.split(";")):
            if statement:
                conn.execute(statement)

    @staticmethod
    def insert_window(conn: sqlite3.Connection, structure_id: str, doc: LoadsWindowDocument, *, at: float = 0.0,
                      replace: bool = False) -> None:
        """Write one window's rows (``replace``: over those of the same window, as ``shm reprocess`` does;
        else a window already stored is kept)."""
        verb = "INSERT OR REPLACE" if replace else "INSERT OR IGNORE"
        start = float(doc.start_s)
        stations = json.dumps([s.model_dump(mode="json") for s in doc.stations])
        conn.execute(f"{verb} INTO fatigue_windows (source, window_start_s, duration_s, temperature_c, stations, created_at) "
                     "VALUES (?, ?, ?, ?, ?, ?)", (structure_id, start, float(doc.duration_s), doc.temperature_c, stations, at))
        rows = []
        for h in doc.hot_spots:
            values = h.model_dump(mode="json")
            rows.append((structure_id, start, h.name, *(json.dumps(values[c]) if c in _JSON else values[c] for c in _SPOT_COLUMNS)))
        conn.executemany(f"{verb} INTO fatigue_hot_spots (source, window_start_s, hot_spot, {', '.join(_SPOT_COLUMNS)}) "
                         f"VALUES ({', '.join('?' * (3 + len(_SPOT_COLUMNS)))})", rows)

    @staticmethod
    def count(conn: sqlite3.Connection, structure_id: str, from_s: float | None = None, to_s: float | None = None) -> int:
        where, args = _conditions(structure_id, from_s, to_s)
        return int(conn.execute(f"SELECT COUNT(*) FROM fatigue_windows WHERE {where}", args).fetchone()[0])

    @staticmethod
    def windows(conn: sqlite3.Connection, structure_id: str, from_s: float | None = None, to_s: float | None = None,
                limit: int = 100_000) -> list[LoadsWindowDocument]:
        """The stored windows with ``from_s <= start < to_s`` (UNIX s), oldest first, at most ``limit``
        (the fatigue charts are not stored: the alarms are)."""
        if isinstance(limit, bool) or not isinstance(limit, int) or limit < 1:
            raise ValueError(f"{limit=} must be an integer >= 1")
        where, args = _conditions(structure_id, from_s, to_s)
        heads = conn.execute(f"SELECT window_start_s, duration_s, temperature_c, stations FROM fatigue_windows WHERE {where} "
                             "ORDER BY window_start_s LIMIT ?", (*args, limit)).fetchall()
        if not heads:
            return []
        lo, hi = heads[0][0], heads[-1][0]
        spots: dict[float, list[HotSpotLoadsDocument]] = {}
        sql = (f"SELECT window_start_s, hot_spot, {', '.join(_SPOT_COLUMNS)} FROM fatigue_hot_spots "
               "WHERE source = ? AND window_start_s >= ? AND window_start_s <= ? ORDER BY window_start_s, position_m, hot_spot")
        for r in conn.execute(sql, (structure_id, lo, hi)):
            values = {c: (json.loads(v) if c in _JSON and v is not None else v) for c, v in zip(_SPOT_COLUMNS, r[2:])}
            spots.setdefault(r[0], []).append(HotSpotLoadsDocument(name=r[1], **values))
        return [LoadsWindowDocument(start_s=start, duration_s=duration, temperature_c=temperature, hot_spots=spots.get(start, []),
                                    stations=[StationLoadsDocument(**s) for s in json.loads(stations)])
                for start, duration, temperature, stations in heads]

    @staticmethod
    def latest(conn: sqlite3.Connection, structure_id: str, to_s: float | None = None) -> LoadsWindowDocument | None:
        """The newest stored window (before ``to_s``), or None."""
        where, args = _conditions(structure_id, None, to_s)
        row = conn.execute(f"SELECT window_start_s FROM fatigue_windows WHERE {where} ORDER BY window_start_s DESC LIMIT 1",
                           args).fetchone()
        if row is None:
            return None
        found = FatigueRepository.windows(conn, structure_id, row[0], None, 1)
        return found[0] if found else None


def fatigue_document(structure_id: str, windows: list[LoadsWindowDocument], total: int,
                     latest: LoadsWindowDocument | None, *, design_life_years: float | None = None) -> FatigueDocument:
    """The ``FatigueDocument`` of a period: the hot spots as the period's newest window left them,
    its windows (the trend) and the strain envelope along the beam over them (largest ranges;
    the RMS over the windows' time). ``design_life_years``: the rig's ``fatigue.design_life_years``
    (the document's design life whether or not a window was stored yet); None: the stored hot
    spots' own."""
    envelope: dict[float, list[float]] = {}  # position -> [Σ rms² duration, Σ duration, range max, stress range max]
    for w in windows:
        for s in w.stations:
            e = envelope.setdefault(s.position_m, [0.0, 0.0, 0.0, 0.0])
            if s.strain_rms is not None:
                e[0] += s.strain_rms**2 * w.duration_s
                e[1] += w.duration_s
            e[2] = max(e[2], s.strain_range_max or 0.0)
            e[3] = max(e[3], s.stress_range_max_pa or 0.0)
    stations = [StationLoadsDocument(position_m=x, strain_rms=math.sqrt(e[0] / e[1]) if e[1] > 0 else None, strain_range_max=e[2],
                                     stress_range_max_pa=e[3]) for x, e in sorted(envelope.items())]
    spots = [] if latest is None else list(latest.hot_spots)
    design = design_life_years if design_life_years is not None else next(
        (h.design_life_years for h in spots if h.design_life_years is not None), None)
    return FatigueDocument(structure_id=structure_id, design_life_years=design, hot_spots=spots, windows=windows,
                           envelope=stations, total=total, truncated=total > len(windows))
