"""Leases of a fleet's structures in the database: which node runs which structure until when.

One row per structure (table ``leases``): its ``holder`` (a node's name; NULL: free), its
``expires_at`` (UNIX s on the DATABASE's clock, so no node's clock is trusted) and its fencing
``token``, increased by every acquisition, by whichever node. A node renews its leases while it
is alive; one that dies loses them when they expire, and another node takes them
(``take_expired``). The token is what makes this safe when the old holder is not dead but only
slow (paused, cut off): every window it commits carries the token of its lease and the commit's
transaction checks it (``check_fence``) under a row lock on the lease. A takeover (which raises
the token) therefore waits for a commit under way, and any commit after it finds its token stale
and is refused (``StaleLease``): a structure's windows are never written by two nodes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from .._commit import StaleLease
from ._db import PgDatabase, check_fence

__all__ = ["Lease", "Leases", "StaleLease", "check_fence"]

_NOW = "(SELECT EXTRACT(EPOCH FROM clock_timestamp())::float8 AS now)"
_RETURNS = "structure_id, holder, token, expires_at, (expires_at IS NULL OR expires_at <= clock.now) AS expired"


@dataclass(frozen=True)
class Lease:
    """A structure's lease as the database held it when read: its ``holder`` (None: free), its
    fencing ``token``, when it expires (database clock, UNIX s) and whether it had."""

    structure_id: str
    holder: str | None
    token: int
    expires_at: float | None
    expired: bool


def _lease(row: Any) -> Lease:
    return Lease(str(row[0]), None if row[1] is None else str(row[1]), int(row[2]),
                 None if row[3] is None else float(row[3]), bool(row[4]))


class Leases:
    """The leases of the database ``url`` (a connection of their own, so that a renewal never
    waits behind the windows being committed). ``lease_s``: how long an acquisition or renewal
    holds. Thread-safe."""

    def __init__(self, url: str, *, lease_s: float = 15.0, connect_timeout_s: float = 5.0) -> None:
        self.lease_s = self._duration(lease_s)
        # a renewal retried longer than a third of the lease would come too late to matter
        self.database = PgDatabase(url, retry_s=self.lease_s / 3, connect_timeout_s=connect_timeout_s)

    @staticmethod
    def _duration(lease_s: float) -> float:
        if not (isinstance(lease_s, (int, float)) and math.isfinite(lease_s) and lease_s > 0):
            raise ValueError(f"{lease_s=} must be a positive number of seconds")
        return float(lease_s)

    def _lease_s(self, lease_s: float | None) -> float:
        return self.lease_s if lease_s is None else self._duration(lease_s)

    def now(self) -> float:
        """The database's clock (UNIX s)."""
        return float(self.database.read(lambda db: db.execute(f"SELECT now FROM {_NOW} AS clock").fetchone()[0]))

    def register(self, structure_ids: Sequence[str]) -> None:
        """A free lease (token 0) for each structure that has none yet."""
        ids = [str(s) for s in structure_ids]
        if ids:
            self.database.write(lambda db: db.executemany(
                "INSERT INTO leases (structure_id, token) VALUES (?, 0) ON CONFLICT (structure_id) DO NOTHING", [(i,) for i in ids]))

    def acquire(self, structure_id: str, node: str, *, lease_s: float | None = None) -> Lease | None:
        """Take the lease of ``structure_id`` for ``node`` when it is free or expired (its token
        increased), or renew it when ``node`` holds it unexpired (token unchanged); None when
        another node holds it unexpired."""
        duration = self._lease_s(lease_s)
        sql = (f"WITH clock AS {_NOW} INSERT INTO leases AS l (structure_id, holder, token, expires_at, acquired_at, renewed_at) "
               "SELECT ?, ?, 1, clock.now + ?, clock.now, clock.now FROM clock "
               "ON CONFLICT (structure_id) DO UPDATE SET holder = EXCLUDED.holder, "
               "token = CASE WHEN l.holder = EXCLUDED.holder AND l.expires_at > EXCLUDED.renewed_at THEN l.token ELSE l.token + 1 END, "
               "acquired_at = CASE WHEN l.holder = EXCLUDED.holder AND l.expires_at > EXCLUDED.renewed_at THEN l.acquired_at "
               "ELSE EXCLUDED.acquired_at END, expires_at = EXCLUDED.expires_at, renewed_at = EXCLUDED.renewed_at "
               "WHERE l.holder IS NULL OR l.expires_at IS NULL OR l.expires_at <= EXCLUDED.renewed_at OR l.holder = EXCLUDED.holder "
               "RETURNING structure_id, holder, token, expires_at, false")
        row = self.database.write(lambda db: db.execute(sql, (structure_id, node, duration)).fetchone())
        return None if row is None else _lease(row)

    def renew(self, lease: Lease, *, lease_s: float | None = None) -> Lease:
        """Extend ``lease`` while its holder and token are the structure's (also after it expired
        if no node took it meanwhile).

        Raises
        ------
        StaleLease
            When another node took it (or it was released): stop running the structure.
        """
        duration = self._lease_s(lease_s)
        sql = (f"UPDATE leases SET expires_at = clock.now + ?, renewed_at = clock.now FROM {_NOW} AS clock "
               f"WHERE structure_id = ? AND holder = ? AND token = ? RETURNING structure_id, holder, token, expires_at, false")
        row = self.database.write(lambda db: db.execute(sql, (duration, lease.structure_id, lease.holder, lease.token)).fetchone())
        if row is None:
            raise StaleLease(f"the lease of {lease.structure_id!r} with token {lease.token} is no longer {lease.holder!r}'s")
        return _lease(row)

    def renew_all(self, node: str, *, lease_s: float | None = None) -> list[Lease]:
        """Extend every unexpired lease of ``node`` in one statement (the heartbeat); the leases
        it still holds. A lease missing from the answer is lost: stop running its structure."""
        duration = self._lease_s(lease_s)
        sql = (f"UPDATE leases SET expires_at = clock.now + ?, renewed_at = clock.now FROM {_NOW} AS clock "
               "WHERE holder = ? AND expires_at > clock.now RETURNING structure_id, holder, token, expires_at, false")
        rows = self.database.write(lambda db: db.execute(sql, (duration, node)).fetchall())
        return sorted((_lease(r) for r in rows), key=lambda x: x.structure_id)

    def release(self, lease: Lease) -> bool:
        """Give ``lease`` back (free at once, its token kept); False when it was no longer ours."""
        sql = "UPDATE leases SET holder = NULL, expires_at = NULL WHERE structure_id = ? AND holder = ? AND token = ?"
        return bool(self.database.write(lambda db: db.execute(sql, (lease.structure_id, lease.holder, lease.token)).rowcount))

    def release_all(self, node: str) -> int:
        """Give back every lease of ``node`` (a clean stop); how many."""
        return int(self.database.write(lambda db: db.execute(
            "UPDATE leases SET holder = NULL, expires_at = NULL WHERE holder = ?", (node,)).rowcount))

    def take_expired(self, node: str, *, limit: int | None = None, lease_s: float | None = None) -> list[Lease]:
        """Give ``node`` the free and expired leases (those expired longest first, then by id),
        at most ``limit``; each token increased. Rows locked by a commit under way are skipped
        (taken at a later call)."""
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 0):
            raise ValueError(f"{limit=} must be an integer >= 0 or None")
        duration = self._lease_s(lease_s)
        sql = (f"WITH clock AS {_NOW}, free AS (SELECT l.structure_id FROM leases AS l, clock "
               "WHERE l.holder IS NULL OR l.expires_at IS NULL OR l.expires_at <= clock.now "
               "ORDER BY l.expires_at NULLS FIRST, l.structure_id LIMIT ? FOR UPDATE OF l SKIP LOCKED) "
               "UPDATE leases SET holder = ?, token = leases.token + 1, expires_at = clock.now + ?, acquired_at = clock.now, "
               "renewed_at = clock.now FROM free, clock WHERE leases.structure_id = free.structure_id "
               "RETURNING leases.structure_id, holder, token, expires_at, false")
        rows = self.database.write(lambda db: db.execute(sql, (limit, node, duration)).fetchall())
        return sorted((_lease(r) for r in rows), key=lambda x: x.structure_id)

    def held(self, node: str) -> list[Lease]:
        """The unexpired leases of ``node``."""
        return [lease for lease in self.all() if lease.holder == node and not lease.expired]

    def all(self) -> list[Lease]:
        """Every structure's lease (the fleet's view: who runs what), by structure id."""
        rows = self.database.read(lambda db: db.execute(
            f"SELECT {_RETURNS} FROM leases, {_NOW} AS clock ORDER BY structure_id").fetchall())
        return [_lease(r) for r in rows]

    def close(self) -> None:
        self.database.close()

