"""One writer per database: the worker processes of a fleet hand their writes (window commits,
baselines, housekeeping) to the front process, whose ``Storage`` is the database's only writer;
they read it themselves (WAL readers never wait for the writer).

The channel is a Unix socket of ``multiprocessing.connection`` (authenticated with a random key
the front hands its workers in their environment): a worker's ``RemoteStorage`` sends
``(method, args, kwargs)`` of a write and waits for its answer; the front's ``WriterServer`` runs
the method on its ``Storage`` (a thread per worker connection, so the windows of all workers meet
in its group commit) and answers the result or the error.

Why nothing committed is lost and nothing doubles when a process is killed (SIGKILL included):

- a window's rows, the monitor state after it and its alarm changes are one transaction of the
  front (``storage._commit``): it is committed whole or not at all, whoever dies when;
- a worker counts a window committed only once the front answered after COMMIT; a window whose
  answer did not come (the front died, the answer timed out) stays pending and is sent again;
  sent again after all, it changes nothing: its rows are ``INSERT OR IGNORE`` by key, the state
  row is the same upsert, an alarm change applies only to an alarm in the state it expects (a
  second "raise" finds the alarm active, a second "clear" none), so no event and no outbox row
  is written twice;
- a worker killed after the front committed its window resumes from that window's stored state
  (it does not redo it); killed before, it redoes it from the state before;
- the front killed: its workers end with it (``--parent-pid``), and their uncommitted windows
  are redone from the stored state by the next start, as after any crash.
"""

from __future__ import annotations

import logging
import os
import shutil
import sqlite3
import tempfile
import threading
from collections.abc import Mapping
from multiprocessing.connection import Client, Connection, Listener
from pathlib import Path
from typing import Any

from ._commit import StaleLease
from .sqlite._db import StorageUnavailable
from ._storage import Storage

__all__ = ["WRITER_ADDRESS", "WRITER_KEY", "WRITES", "RemoteStorage", "WriterServer", "open_storage"]

log = logging.getLogger("shm.serve.writer")

#: the environment of a worker process: the writer's socket and its key (hex)
WRITER_ADDRESS = "SHM_STORAGE_WRITER"
WRITER_KEY = "SHM_STORAGE_WRITER_KEY"

#: the methods of ``Storage`` that write: a worker sends these to the writer
WRITES = frozenset({"commit_window", "commit_reprocessed", "touch_source", "touch_sources", "save_calibration",
                    "request_baseline", "store_baseline", "renotify_due", "mark_stale", "delete_trends_older_than",
                    "acknowledge", "record_attempt", "fail_pending", "claim_notification"})

#: the errors that cross the channel as themselves (any other: RuntimeError naming it)
_KINDS: dict[str, type[Exception]] = {"StorageUnavailable": StorageUnavailable, "ValueError": ValueError,
                                      "KeyError": KeyError, "PermissionError": PermissionError,
                                      "StaleLease": StaleLease}


class WriterServer:
    """The front's end of the channel: runs the writes its workers send on ``storage``."""

    def __init__(self, storage: Storage) -> None:
        self.storage = storage
        self.key = os.urandom(16)
        # a short path: a Unix socket's address is limited to ~100 bytes, a data directory is not
        self._directory = Path(tempfile.mkdtemp(prefix="shm-writer-"))
        self.address = str(self._directory / "writer.sock")
        self._listener = Listener(self.address, family="AF_UNIX", authkey=self.key)
        self._connections: list[Connection] = []
        self._lock = threading.Lock()
        self._closed = False
        self.calls = 0  # writes run for the workers
        threading.Thread(target=self._accept, name="storage-writer", daemon=True).start()

    def environ(self) -> dict[str, str]:
        """What a worker's environment needs to write through this writer."""
        return {WRITER_ADDRESS: self.address, WRITER_KEY: self.key.hex()}

    def _accept(self) -> None:
        while not self._closed:
            try:
                connection = self._listener.accept()
            except (OSError, EOFError):
                if self._closed:
                    return
                continue  # a client that failed the authentication
            with self._lock:
                self._connections.append(connection)
            threading.Thread(target=self._serve, args=(connection,), name="storage-writer-client", daemon=True).start()

    def _serve(self, connection: Connection) -> None:
        try:
            while True:
                try:
                    method, args, kwargs = connection.recv()
                except (EOFError, OSError):
                    return  # the worker ended (or was killed): what it committed is committed
                connection.send(self._run(method, args, kwargs))
        except (OSError, EOFError) as exc:
            log.info("a worker went away before its answer: %s (its write is committed or not, whole)", exc)
        except Exception:
            if not self._closed:  # stop() closed the connection under this thread: nothing to say
                raise
        finally:
            connection.close()

    def _run(self, method: str, args: tuple, kwargs: dict) -> tuple:
        if method not in WRITES:
            return ("error", "ValueError", f"{method!r} is not a write of the storage")
        try:
            result = getattr(self.storage, method)(*args, **kwargs)
        except Exception as exc:
            kind = type(exc).__name__
            text = str(exc) if kind in _KINDS else f"{kind}: {exc}"
            if isinstance(exc, sqlite3.Error) and not isinstance(exc, StorageUnavailable):
                kind = "RuntimeError"
            return ("error", kind, text)
        self.calls += 1
        return ("ok", result)

    def stop(self) -> None:
        """No more writes: after the workers ended (their last windows are written first)."""
        self._closed = True
        self._listener.close()
        with self._lock:
            for connection in self._connections:
                connection.close()
        shutil.rmtree(self._directory, ignore_errors=True)


class RemoteStorage(Storage):
    """A worker's storage: reads from the database itself, writes through the front's writer
    (``WRITES``). A write that gets no answer within ``answer_s`` (or whose channel broke) raises
    ``StorageUnavailable``: the caller keeps it and sends it again (see the module's docstring)."""

    def __init__(self, path: str | Path, address: str, key: bytes, *, answer_s: float = 120.0, **kwargs: Any) -> None:
        super().__init__(path, **kwargs)
        self.address = address
        self._key = key
        self.answer_s = float(answer_s)
        self._channel: Connection | None = None
        self._channel_lock = threading.Lock()

    def _call(self, method: str, *args: Any, **kwargs: Any) -> Any:
        with self._channel_lock:  # one write at a time per worker: the front groups the workers' windows
            try:
                if self._channel is None:
                    self._channel = Client(self.address, family="AF_UNIX", authkey=self._key)
                self._channel.send((method, args, kwargs))
                if not self._channel.poll(self.answer_s):
                    raise TimeoutError(f"no answer within {self.answer_s:g} s")
                answer = self._channel.recv()
            except (OSError, EOFError, TimeoutError) as exc:
                if self._channel is not None:
                    self._channel.close()
                self._channel = None  # a late answer must not be taken for the next call's
                raise StorageUnavailable(f"the database's writer (the fleet's front process) does not answer: {exc}") from None
        if answer[0] == "ok":
            return answer[1]
        _, kind, text = answer
        raise _KINDS.get(kind, RuntimeError)(text)

    def close(self) -> None:
        with self._channel_lock:
            if self._channel is not None:
                self._channel.close()
                self._channel = None
        super().close()


def _forwarding(method: str) -> Any:
    def forward(self: RemoteStorage, *args: Any, **kwargs: Any) -> Any:
        return self._call(method, *args, **kwargs)

    forward.__name__ = method
    forward.__doc__ = f"``Storage.{method}``, run by the database's writer."
    return forward


for _method in WRITES:
    setattr(RemoteStorage, _method, _forwarding(_method))


def open_storage(path: str | Path, *, environ: Mapping[str, str] | None = None, **kwargs: Any) -> Storage:
    """The storage of this process: a worker of a fleet (``WRITER_ADDRESS`` in its environment)
    writes through its front's writer, any other process writes itself."""
    env = os.environ if environ is None else environ
    address = env.get(WRITER_ADDRESS)
    if not address:
        return Storage(path, **kwargs)
    try:
        key = bytes.fromhex(env.get(WRITER_KEY, ""))
    except ValueError:
        raise ValueError(f"{WRITER_KEY} is not the hex key of the writer at {address}") from None
    return RemoteStorage(path, address, key, **kwargs)
