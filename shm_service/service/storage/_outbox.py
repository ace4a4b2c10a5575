"""The delivery side of the notification outbox: which rows are due, and each attempt logged
with the row's new status in one transaction (the alarm side, which fills the outbox in the
window's transaction, is ``AlarmRepository.event``).

``OutboxStore`` is what the notifier needs, ``OutboxRepository`` implements it over one SQLite
connection (no transactions, no retries: the caller's)."""

from __future__ import annotations

import sqlite3
from typing import Any, Protocol

__all__ = ["OutboxRepository", "OutboxStore"]


class OutboxStore(Protocol):
    def due(self, now: float, limit: int, channel: str | None, target: str | None) -> list[dict[str, Any]]: ...

    def next_due(self, channel: str, target: str) -> float | None: ...

    def pending_targets(self) -> list[tuple[str, str]]: ...

    def record_attempt(self, outbox_id: int, ok: bool, detail: str, now: float, *, next_attempt_at: float | None,
                       give_up: bool, permanent: bool = False) -> None: ...

    def fail_pending(self, channel: str, target: str, detail: str) -> int: ...

    def claim(self, outbox_id: int, now: float, hold_s: float) -> bool: ...

    def rows(self, table: str) -> list[dict[str, Any]]: ...

    def counts(self) -> dict[str, int]: ...


class OutboxRepository:
    """``OutboxStore`` over the SQLite connection ``db`` (tables outbox, notification_log)."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self.db = db

    def due(self, now: float, limit: int, channel: str | None, target: str | None) -> list[dict[str, Any]]:
        """Pending rows due at ``now``, oldest first; of one target when given. A row waits while
        an earlier row of the same alarm and target is still pending: each target gets an alarm's
        events in their order, whatever their retries."""
        pairs = [("o.next_attempt_at <= ?", now), ("o.channel = ?", channel), ("o.target = ?", target)]
        where = ["o.status='pending'"] + [sql for sql, value in pairs if value is not None]
        args: list[Any] = [value for _, value in pairs if value is not None]
        sql = (f"SELECT o.* FROM outbox AS o WHERE {' AND '.join(where)} AND NOT EXISTS (SELECT 1 FROM outbox AS p "
               "WHERE p.status='pending' AND p.channel=o.channel AND p.target=o.target AND p.alarm_id IS o.alarm_id "
               "AND p.id < o.id) ORDER BY o.id LIMIT ?")
        return [dict(r) for r in self.db.execute(sql, [*args, limit]).fetchall()]

    def next_due(self, channel: str, target: str) -> float | None:
        """When the earliest pending row of a target is due (UNIX s), None when there is none."""
        row = self.db.execute("SELECT MIN(next_attempt_at) FROM outbox WHERE status='pending' AND channel=? AND target=?",
                              (channel, target)).fetchone()
        return None if row[0] is None else float(row[0])

    def pending_targets(self) -> list[tuple[str, str]]:
        """(channel, target) of every pending row."""
        rows = self.db.execute("SELECT DISTINCT channel, target FROM outbox WHERE status='pending' "
                               "ORDER BY channel, target").fetchall()
        return [(r["channel"], r["target"]) for r in rows]

    def record_attempt(self, outbox_id: int, ok: bool, detail: str, now: float, *, next_attempt_at: float | None,
                       give_up: bool, permanent: bool = False) -> None:
        """Log one delivery attempt and mark the row sent, failed (``give_up``; ``permanent``: the
        target refused it for good) or due again."""
        row = self.db.execute("SELECT attempts FROM outbox WHERE id=?", (outbox_id,)).fetchone()
        if row is None:
            raise KeyError(f"outbox row {outbox_id} does not exist")
        attempt = int(row["attempts"]) + 1
        self.db.execute("INSERT INTO notification_log (outbox_id, attempt, at, ok, detail) VALUES (?, ?, ?, ?, ?)",
                        (outbox_id, attempt, now, int(ok), detail[:500]))
        if ok:
            self.db.execute("UPDATE outbox SET status='sent', attempts=?, sent_at=?, last_error=NULL WHERE id=?",
                            (attempt, now, outbox_id))
        elif give_up:
            self.db.execute("UPDATE outbox SET status='failed', attempts=?, last_error=?, permanent=? WHERE id=?",
                            (attempt, detail[:500], int(permanent), outbox_id))
        else:
            self.db.execute("UPDATE outbox SET attempts=?, next_attempt_at=?, last_error=? WHERE id=?",
                            (attempt, next_attempt_at, detail[:500], outbox_id))

    def claim(self, outbox_id: int, now: float, hold_s: float) -> bool:
        """Take a due pending row for one delivery attempt: it is not due again for ``hold_s``
        (then the attempt's record sets its state); False when it is no longer due (another
        notifier took it, or it was delivered)."""
        cur = self.db.execute("UPDATE outbox SET next_attempt_at=? WHERE id=? AND status='pending' AND next_attempt_at <= ?",
                              (now + hold_s, outbox_id, now))
        return bool(cur.rowcount)

    def fail_pending(self, channel: str, target: str, detail: str) -> int:
        """Mark failed (for good) every pending row of a target no longer configured."""
        cur = self.db.execute("UPDATE outbox SET status='failed', last_error=?, permanent=1 WHERE status='pending' "
                              "AND channel=? AND target=?", (detail[:500], channel, target))
        return int(cur.rowcount)

    def rows(self, table: str) -> list[dict[str, Any]]:
        """Every row of ``outbox`` or ``notification_log``, in order."""
        if table not in ("outbox", "notification_log"):
            raise ValueError(f"{table=} must be 'outbox' or 'notification_log'")
        return [dict(r) for r in self.db.execute(f"SELECT * FROM {table} ORDER BY id").fetchall()]

    def counts(self) -> dict[str, int]:
        rows = self.db.execute("SELECT status, COUNT(*) AS n FROM outbox GROUP BY status").fetchall()
        return {r["status"]: int(r["n"]) for r in rows}
