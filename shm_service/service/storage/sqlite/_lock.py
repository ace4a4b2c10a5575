"""One service per database: a lock file beside the database naming its holder.

``DB.lock`` (beside ``DB``) holds one JSON line: the holder's ``pid``, ``host``, ``started``
(UNIX s) and command line. The holder keeps an exclusive ``flock`` on the file for its life, so

- a second service (``shm serve``, a fleet's front process) that cannot take the ``flock`` finds
  the database served: it refuses to start with an error naming the holder's process and host;
- the kernel drops the ``flock`` when the holder dies (killed, crashed): the next service takes
  the ``flock``, finds the stale record of a dead process and takes the lock over (it says so);
- a lock written on another host (a database on a shared disk whose ``flock`` does not reach
  across hosts) is honoured while the record's process could be alive there: the error names it
  and says how to clear it.

A fleet's worker processes run under their front process's lock and take none themselves.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["DatabaseBusy", "DatabaseLock"]


class DatabaseBusy(RuntimeError):
    """The database is served by another process (the message names it)."""


class _Replaced(Exception):
    """The lock file was removed and made anew while this process opened it."""


def _describe(holder: dict[str, Any]) -> str:
    started = holder.get("started")
    when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(started)) if isinstance(started, (int, float)) else "?"
    return f"process {holder.get('pid')} on host {holder.get('host')!r} (since {when}: {holder.get('command', '?')})"


class DatabaseLock:
    """The lock of ``database`` held by this process; :meth:`acquire` takes it, :meth:`release`
    (or leaving the ``with`` block) gives it back. ``took_over`` describes a stale holder replaced."""

    def __init__(self, path: Path, fd: int, took_over: str | None) -> None:
        self.path = path
        self._fd: int | None = fd
        self.took_over = took_over

    @staticmethod
    def path_of(database: str | os.PathLike[str]) -> Path:
        db = Path(database)
        return db.with_name(db.name + ".lock")

    @classmethod
    def acquire(cls, database: str | os.PathLike[str]) -> "DatabaseLock":
        """Take the lock of ``database``.

        Raises
        ------
        DatabaseBusy
            If another live process holds it (named in the message).
        OSError
            If the lock file cannot be created.
        """
        path = cls.path_of(database)
        path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(5):
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                return cls._take(fd, path, database)
            except _Replaced:
                continue  # the holder released (and removed) the file between our open and flock
        raise DatabaseBusy(f"the lock {path} of the database {database} keeps changing hands: another service starts and stops")

    @classmethod
    def _take(cls, fd: int, path: Path, database: str | os.PathLike[str]) -> "DatabaseLock":
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = cls._read(fd)
                raise DatabaseBusy(f"the database {database} is served by {_describe(holder)} (lock {path}): "
                                   "one service per database; stop that one or give another --db") from None
            try:
                current = os.stat(path).st_ino
            except FileNotFoundError:
                current = None
            if current != os.fstat(fd).st_ino:
                raise _Replaced
            holder = cls._read(fd)
            took_over = None
            me = socket.gethostname()
            if holder:
                pid, host = holder.get("pid"), holder.get("host")
                if host != me and isinstance(pid, int):
                    raise DatabaseBusy(f"the database {database} is locked by {_describe(holder)} (lock {path}), another "
                                       f"host whose processes this one cannot see: if that service has stopped, delete {path}")
                took_over = f"took over the stale lock of {_describe(holder)}"
            record = {"pid": os.getpid(), "host": me, "started": time.time(), "command": " ".join(sys.argv[:6])}
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
            os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        return cls(path, fd, took_over)

    @staticmethod
    def _read(fd: int) -> dict[str, Any]:
        try:
            text = os.pread(fd, 4096, 0).decode(errors="replace").strip()
            doc = json.loads(text) if text else {}
            return doc if isinstance(doc, dict) else {}
        except (OSError, ValueError):
            return {}

    def release(self) -> None:
        """Remove the record and drop the flock (idempotent)."""
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        try:
            os.ftruncate(fd, 0)
            self.path.unlink(missing_ok=True)
        except OSError:
            pass
        finally:
            os.close(fd)

    def __enter__(self) -> "DatabaseLock":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
