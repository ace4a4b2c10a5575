"""The alarms, their events and the notification outbox the events fill, in one repository:
an alarm's change, its event and the event's outbox rows are always written together (in the
window's transaction), so a crash loses or doubles no notification.

``AlarmStore`` is what the service needs, ``AlarmRepository`` implements it over one SQLite
connection (no transactions, no retries: the caller's). The delivery side of the outbox (due
rows, attempts) is ``OutboxRepository`` in ``storage._outbox``."""

from __future__ import annotations

import math
import sqlite3
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from pydantic import TypeAdapter

from contract import AlarmDocument, AlarmEventDocument

__all__ = ["ALARM_COLUMNS", "AlarmChange", "AlarmQuery", "AlarmRepository", "AlarmStore", "NotifyPolicy"]

#: The alarm table's columns are the alarm document's fields.
ALARM_COLUMNS = tuple(AlarmDocument.model_fields)
_ALARMS = TypeAdapter(list[AlarmDocument])


def _finite(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class AlarmChange:
    """What the alarm logic decided for one chart in one window.

    ``action``: "raise" (new alarm at ``level``), "escalate" (the active alarm of the chart goes
    to "alarm"), "clear" (the active alarm of the chart clears)."""

    action: str
    chart: str
    kind: str
    mode: int | None
    level: str
    at_s: float
    value: float | None
    threshold: float | None
    message: str


@dataclass(frozen=True)
class NotifyPolicy:
    """Which events notify whom: (channel, target) pairs, the levels whose raise, escalation and
    repetition notify, whether clearing and going stale do; ``instance``: the database's random id
    (a notification's id is ``shm-{instance}-{event uuid}``)."""

    instance: str
    targets: tuple[tuple[str, str], ...] = ()
    levels: tuple[str, ...] = ("warning", "alarm")
    cleared: bool = True
    stale: bool = True

    def notifies(self, event: str, level: str) -> bool:
        if event in ("raised", "escalated", "repeated"):
            return level in self.levels
        if event == "cleared":
            return self.cleared
        if event == "stale":
            return self.stale
        if event == "acknowledged":
            return False
        raise ValueError(f"unknown alarm event {event!r}")


@dataclass(frozen=True)
class AlarmQuery:
    """Which alarms: in ``state`` ("active", "cleared"; None: both), of ``source`` (None: all)."""

    state: str | None = None
    source: str | None = None

    def __post_init__(self) -> None:
        if self.state not in (None, "active", "cleared"):
            raise ValueError(f"state={self.state!r} must be 'active', 'cleared' or None")


class AlarmStore(Protocol):
    """Alarms (newest first), their events and the outbox rows of the events that notify."""

    name: str

    def apply(self, source: str, change: AlarmChange, now: float) -> int | None: ...

    def event(self, alarm_id: int, event: str, level: str, at_s: float, now: float, *, notify: bool | None = None) -> int: ...

    def clear_stale(self, sources: Sequence[str]) -> None: ...

    def due_for_repeat(self, before: float) -> list[tuple[int, str]]: ...

    def silent(self, silent_since: float) -> list[tuple[int, str]]: ...

    def mark_stale(self, alarm_id: int) -> None: ...

    def get(self, alarm_id: int) -> AlarmDocument | None: ...

    def newest(self, query: AlarmQuery, limit: int) -> list[AlarmDocument]: ...

    def acknowledge(self, alarm_id: int, by: str, now: float) -> bool: ...

    def count(self, query: AlarmQuery, after: tuple | None) -> int: ...

    def key_at(self, query: AlarmQuery, after: tuple | None, offset: int) -> tuple | None: ...

    def chunks(self, query: AlarmQuery, after: tuple | None, limit: int) -> Iterator[list[AlarmDocument]]: ...

    def events(self) -> list[dict[str, Any]]: ...


class AlarmRepository:
    """``AlarmStore`` over the SQLite connection ``db`` (tables alarms, alarm_events, outbox)."""

    name = "alarms"
    key_types: tuple[type, ...] = (int,)

    def __init__(self, db: sqlite3.Connection, policy: NotifyPolicy | None = None, chunk_rows: int = 2000) -> None:
        self.db = db
        self.policy = policy
        self.chunk_rows = int(chunk_rows)

    def apply(self, source: str, change: AlarmChange, now: float) -> int | None:
        """Apply a change of the alarm logic; the id of the event written (None: nothing changed)."""
        active = self.db.execute(
            "SELECT id, level FROM alarms WHERE source=? AND chart=? AND state='active' ORDER BY id DESC LIMIT 1",
            (source, change.chart)).fetchone()
        if change.action == "raise":
            if active is not None:
                return None
            cur = self.db.execute(
                "INSERT OR IGNORE INTO alarms (source, chart, kind, mode, level, state, raised_at_s, value, threshold, message) "
                "VALUES (?, ?, ?, ?, ?, 'active', ?, ?, ?, ?)",
                (source, change.chart, change.kind, change.mode, change.level, change.at_s, _finite(change.value),
                 _finite(change.threshold), change.message))
            if not cur.rowcount:
                return None
            alarm_id, event = int(cur.lastrowid or 0), "raised"
        elif change.action == "escalate":
            if active is None or active[1] == "alarm":
                return None
            alarm_id, event = int(active[0]), "escalated"
            self.db.execute("UPDATE alarms SET level='alarm', value=?, threshold=?, message=? WHERE id=?",
                            (_finite(change.value), _finite(change.threshold), change.message, alarm_id))
        elif change.action == "clear":
            if active is None:
                return None
            alarm_id, event = int(active[0]), "cleared"
            self.db.execute("UPDATE alarms SET state='cleared', cleared_at_s=? WHERE id=?", (change.at_s, alarm_id))
        else:
            raise ValueError(f"unknown alarm action {change.action!r}")
        return self.event(alarm_id, event, change.level, change.at_s, now)

    def event(self, alarm_id: int, event: str, level: str, at_s: float, now: float, *, notify: bool | None = None) -> int:
        """Insert an alarm event (its per-alarm sequence number and UUID) and, when it notifies,
        its outbox rows, one per target."""
        if self.policy is None:
            raise RuntimeError("an AlarmRepository without a NotifyPolicy only reads")
        seq = int(self.db.execute("SELECT COALESCE(MAX(seq), 0) + 1 FROM alarm_events WHERE alarm_id=?",
                                  (alarm_id,)).fetchone()[0])
        event_uuid = uuid.uuid4().hex
        cur = self.db.execute(
            "INSERT INTO alarm_events (alarm_id, seq, uuid, event, level, at_s, created_at) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (alarm_id, seq, event_uuid, event, level, at_s, now))
        event_id = int(cur.lastrowid or 0)
        if notify is None:
            notify = self.policy.notifies(event, level)
        if notify and self.policy.targets:
            alarm = self.get(alarm_id)
            payload = AlarmEventDocument(id=f"shm-{self.policy.instance}-{event_uuid}", event=event,
                                         sequence=seq, level=level, at_s=at_s, alarm=alarm).model_dump_json()
            self.db.executemany(
                "INSERT OR IGNORE INTO outbox (event_id, alarm_id, channel, target, payload, status, next_attempt_at, created_at) "
                "VALUES (?, ?, ?, ?, ?, 'pending', ?, ?)",
                [(event_id, alarm_id, channel, target, payload, now, now) for channel, target in self.policy.targets])
        return event_id

    def clear_stale(self, sources: Sequence[str]) -> None:
        """The sources are judged again: their alarms are no longer stale."""
        for source in sources:
            self.db.execute("UPDATE alarms SET stale=0 WHERE source=? AND stale=1", (source,))

    def due_for_repeat(self, before: float) -> list[tuple[int, str]]:
        """(id, level) of the active, non-stale alarms whose last notified event is older than ``before``."""
        rows = self.db.execute(
            "SELECT a.id, a.level FROM alarms AS a WHERE a.state='active' AND a.stale=0 AND "
            "(SELECT MAX(e.created_at) FROM alarm_events AS e WHERE e.alarm_id=a.id AND "
            "e.event IN ('raised', 'escalated', 'repeated')) <= ?", (before,)).fetchall()
        return [(int(r[0]), str(r[1])) for r in rows]

    def silent(self, silent_since: float) -> list[tuple[int, str]]:
        """(id, level) of the active, non-stale alarms of the sources not seen since ``silent_since``."""
        rows = self.db.execute("SELECT a.id, a.level FROM alarms AS a JOIN sources AS s ON s.id = a.source "
                               "WHERE a.state='active' AND a.stale=0 AND s.last_seen_s < ?", (silent_since,)).fetchall()
        return [(int(r[0]), str(r[1])) for r in rows]

    def mark_stale(self, alarm_id: int) -> None:
        self.db.execute("UPDATE alarms SET stale=1 WHERE id=?", (alarm_id,))

    def get(self, alarm_id: int) -> AlarmDocument | None:
        row = self.db.execute(f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms WHERE id=?", (alarm_id,)).fetchone()
        return None if row is None else AlarmDocument.model_validate(dict(zip(ALARM_COLUMNS, row)))

    def acknowledge(self, alarm_id: int, by: str, now: float) -> bool:
        """Acknowledge (idempotent: a second acknowledgement keeps the first); False: no such alarm."""
        row = self.db.execute("SELECT level, acknowledged_at_s FROM alarms WHERE id=?", (alarm_id,)).fetchone()
        if row is None:
            return False
        if row[1] is None:
            self.db.execute("UPDATE alarms SET acknowledged_at_s=?, acknowledged_by=? WHERE id=?", (now, by, alarm_id))
            self.event(alarm_id, "acknowledged", row[0], now, now, notify=False)
        return True

    @staticmethod
    def _where(query: AlarmQuery, after: tuple | None) -> tuple[str, list]:
        pairs = [("state = ?", query.state), ("source = ?", query.source), ("id < ?", None if after is None else after[0])]
        where = [sql for sql, value in pairs if value is not None]
        return (" WHERE " + " AND ".join(where)) if where else "", [value for _, value in pairs if value is not None]

    def count(self, query: AlarmQuery, after: tuple | None) -> int:
        where, args = self._where(query, after)
        return int(self.db.execute(f"SELECT COUNT(*) FROM alarms{where}", args).fetchone()[0])

    def key_at(self, query: AlarmQuery, after: tuple | None, offset: int) -> tuple | None:
        where, args = self._where(query, after)
        row = self.db.execute(f"SELECT id FROM alarms{where} ORDER BY id DESC LIMIT 1 OFFSET ?", [*args, offset]).fetchone()
        return None if row is None else (int(row[0]),)

    def chunks(self, query: AlarmQuery, after: tuple | None, limit: int) -> Iterator[list[AlarmDocument]]:
        where, args = self._where(query, after)
        cursor = self.db.execute(f"SELECT {', '.join(ALARM_COLUMNS)} FROM alarms{where} ORDER BY id DESC LIMIT ?",
                                 [*args, int(limit)])
        while True:
            rows = cursor.fetchmany(self.chunk_rows)
            if not rows:
                return
            yield _ALARMS.validate_python([dict(zip(ALARM_COLUMNS, r)) for r in rows])

    def newest(self, query: AlarmQuery, limit: int) -> list[AlarmDocument]:
        return [a for chunk in self.chunks(query, None, limit) for a in chunk]

    def events(self) -> list[dict[str, Any]]:
        cursor = self.db.execute("SELECT * FROM alarm_events ORDER BY id")
        names = [d[0] for d in cursor.description]
        return [dict(zip(names, r)) for r in cursor.fetchall()]
