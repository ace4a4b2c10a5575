"""The process side of ``shm serve``: how a started process says it is ready, how it ends with the
process that started it, and how a fleet's front finds the workers of an earlier front.

- **Readiness** is a JSON document written atomically (a temporary file renamed over the path) to
  the file named by ``--ready-file``: ``{"version": 1, "pid", "state", "api", "docs", "dashboard",
  ...}``. The human banner ("API at ...") stays for people; no program parses it.
- **Parent death**: with ``--parent-pid PID`` the process ends when that process ends, however it
  ends (SIGKILL and the OOM killer included). On Linux the kernel sends SIGTERM at once
  (``prctl(PR_SET_PDEATHSIG)``, asked for only when the starting thread is the parent's main thread,
  since the kernel signals when that *thread* ends); everywhere a watcher thread sees the process
  re-parented (``os.getppid()`` no longer the parent) within ``PARENT_POLL_S``. Either starts the
  ordinary graceful stop; a process still alive ``PARENT_GRACE_S`` later ends hard.
- **Stale workers**: every worker holds a shared ``flock`` on ``<db>.workers.lock`` for its life and
  the front records the workers' pids in ``<db>.workers.json``. A front that starts takes the lock
  exclusively first: when it cannot, workers of an earlier front still run on the database; it
  ends them (SIGTERM, then SIGKILL) before it starts its own.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import signal
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..._lifetime import set_parent_death_signal

__all__ = [
    "PARENT_GRACE_S", "PARENT_POLL_S", "READY_VERSION", "StaleWorkers", "end_with_parent", "hold_worker_lock",
    "read_ready", "record_workers", "stale_worker_pids", "stop_stale_workers", "write_ready",
]

log = logging.getLogger("shm.serve.processes")

READY_VERSION = 1
#: how often the watcher looks at its parent (s)
PARENT_POLL_S = 0.2
#: how long a process whose parent ended may drain before it ends hard (s)
PARENT_GRACE_S = 5.0
#: environment variable by which a starter says its spawning thread is its main thread
DEATHSIG_ENV = "SHM_PARENT_DEATHSIG"


# -- readiness --------------------------------------------------------------------------------


def write_ready(path: str | os.PathLike[str], document: Mapping[str, Any]) -> None:
    """Write the ready document ``document`` to ``path`` atomically (a reader sees all or nothing)."""
    target = Path(path)
    doc = {"version": READY_VERSION, "pid": os.getpid(), **document}
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(doc), encoding="utf-8")
    os.replace(tmp, target)


def read_ready(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ready document at ``path`` (None: not written yet)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    doc = json.loads(text)
    if not isinstance(doc, dict) or doc.get("version") != READY_VERSION:
        raise ValueError(f"{path}: not a ready document of version {READY_VERSION}: {text[:200]!r}")
    return doc


# -- ending with the parent ----------------------------------------------------------------------


def end_with_parent(parent_pid: int, *, environ: Mapping[str, str] | None = None, grace_s: float = PARENT_GRACE_S,
                    poll_s: float = PARENT_POLL_S) -> threading.Thread:
    """End this process when process ``parent_pid`` (its parent) ends.

    The end starts as a SIGTERM to this process (its handler stops it gracefully); a process still
    alive ``grace_s`` later exits hard (status 3). Returns the watcher thread (a daemon).

    Raises
    ------
    ValueError
        ``parent_pid`` is not a positive pid.
    """
    if int(parent_pid) <= 0:
        raise ValueError(f"parent_pid {parent_pid!r} must be a positive process id")
    env = os.environ if environ is None else environ
    if env.get(DEATHSIG_ENV) == "1":
        set_parent_death_signal(signal.SIGTERM)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        # The hard end first, from the kernel: SIGALRM's default action ends the process even while a
        # thread holds the GIL through a long call (a graceful stop under load took 11 s).
        if hasattr(signal, "alarm") and signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None):
            signal.alarm(max(1, math.ceil(grace_s)))
        log.warning("the process that started this one (pid %d) ended: stopping (at most %.0f s)", parent_pid, grace_s)
        with contextlib.suppress(OSError):
            os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(grace_s)
        log.error("still running %.0f s after the parent ended: exiting hard", grace_s)
        os._exit(3)

    thread = threading.Thread(target=watch, name="parent-watch", daemon=True)
    thread.start()
    return thread


def child_environ(environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment for a child that should end with this process: with the PDEATHSIG request
    only when this thread is the main thread (the kernel signals when the spawning thread ends)."""
    env = dict(os.environ if environ is None else environ)
    if threading.current_thread() is threading.main_thread():
        env[DEATHSIG_ENV] = "1"
    else:
        env.pop(DEATHSIG_ENV, None)
    return env


# -- stale workers on a database -----------------------------------------------------------------


class StaleWorkers(RuntimeError):
    """Workers of an earlier front still hold the database and did not end."""


def _lock_path(db: str | os.PathLike[str]) -> Path:
    return Path(f"{os.fspath(db)}.workers.lock")


def _pids_path(db: str | os.PathLike[str]) -> Path:
    return Path(f"{os.fspath(db)}.workers.json")


def hold_worker_lock(db: str | os.PathLike[str]) -> Any:
    """Take the shared worker lock of database ``db`` for this process's life (the returned file
    must stay open). None where ``fcntl`` is missing."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return None
    handle = open(_lock_path(db), "a+b")  # noqa: SIM115 - held for the process's life
    fcntl.flock(handle.fileno(), fcntl.LOCK_SH)
    return handle


def record_workers(db: str | os.PathLike[str], pids: Sequence[int]) -> None:
    """Record the worker pids of this front next to database ``db``."""
    write_ready(_pids_path(db), {"front": os.getpid(), "workers": [int(p) for p in pids]})


def _cmdline(pid: int) -> list[str] | None:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return None
    return [part.decode(errors="replace") for part in raw.split(b"\0") if part]


def _is_worker_of(pid: int, config: str | None) -> bool:
    """Whether ``pid`` is a ``shm serve --worker-of`` process (of ``config`` when given). Where
    ``/proc`` is missing a live recorded pid is taken for one."""
    if not Path("/proc/self/cmdline").exists():
        try:
            os.kill(pid, 0)
        except OSError:
            return False
        return True
    cmd = _cmdline(pid)
    if not cmd or "--worker-of" not in cmd or "serve" not in cmd:
        return False
    return config is None or config in cmd


def stale_worker_pids(db: str | os.PathLike[str], config: str | None = None) -> list[int]:
    """The pids of earlier workers on ``db``: the recorded ones still alive, and (where ``/proc``
    exists) any ``shm serve --worker-of`` process of the same configuration file."""
    found: set[int] = set()
    with contextlib.suppress(ValueError, OSError, TypeError):
        doc = read_ready(_pids_path(db))
        for pid in (doc or {}).get("workers", []):
            if int(pid) != os.getpid() and _is_worker_of(int(pid), None):
                found.add(int(pid))
    if config is not None and Path("/proc").is_dir():
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) != os.getpid() and _is_worker_of(int(entry.name), config):
                found.add(int(entry.name))
    return sorted(found)


@contextlib.contextmanager
def _exclusive(db: str | os.PathLike[str], timeout_s: float) -> Iterator[bool]:
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield True
        return
    with open(_lock_path(db), "a+b") as handle:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    yield False
                    return
                time.sleep(0.05)
                continue
            try:
                yield True
            finally:
                fcntl.flock(handle.fileno(), fcntl.LOCK_UN)
            return


def stop_stale_workers(db: str | os.PathLike[str], config: str | None = None, *, term_s: float = 10.0,
                       kill_s: float = 5.0) -> list[int]:
    """Before a front starts its workers on ``db``: end the workers an earlier front left running
    (SIGTERM, SIGKILL after ``term_s``). Returns the pids it ended.

    Raises
    ------
    StaleWorkers
        Workers still hold the database ``kill_s`` after SIGKILL.
    """
    ended: list[int] = []
    with _exclusive(db, 0.0) as free:
        if free:
            return ended
    for signum, wait_s in ((signal.SIGTERM, term_s), (signal.SIGKILL, kill_s)):
        pids = stale_worker_pids(db, config)
        for pid in pids:
            log.warning("a worker of an earlier front (pid %d) still runs on %s: sending %s", pid, db,
                        signal.Signals(signum).name)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signum)
            ended.append(pid)
        with _exclusive(db, wait_s) as free:
            if free:
                return sorted(set(ended))
    raise StaleWorkers(f"workers of an earlier front still hold {db} (pids {stale_worker_pids(db, config) or 'unknown'}); "
                       "end them before starting this service")
