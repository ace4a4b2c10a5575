"""Retention: what the service keeps of the past on disk.

Recordings (the archive's MCAP files) are limited by size (the whole directory's archive files,
oldest first) and by age (a file goes once all of its data are older than the limit before the
newest data of its source); the file being written and the newest file of each source are never
deleted. Trend rows are limited by age (``Storage.delete_trends_older_than``). Ages are in data time,
so a replay of last year's recording keeps what it writes.

``plan_recording_retention`` is the pure decision (files in, files to delete out);
``RetentionWorker`` runs it and the trend limit at start and every ``interval_s`` in a thread of its
own, so a slow disk never holds up the pipeline; a failure is logged and counted, never fatal.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from ._archive_names import parse_archive_name

__all__ = ["RecordingFile", "RetentionSettings", "RetentionWorker", "list_recordings", "plan_recording_retention"]

log = logging.getLogger("shm.serve.retention")

_DAY_S = 86400.0


class RetentionSettings(BaseModel):
    """What the service keeps of the past. Ages are in data time (the newest sample or window), so a
    replay of old data keeps what it writes. Checked at start and every ``interval_s``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    recordings_max_gb: float = Field(
        100.0, gt=0, description="most disk the recordings may take, GB (oldest files go first); the default holds "
        "a week of the benchmark rig: 0.52 GB per hour of data (raw samples and 50 Hz estimates, measured), 87 GB a week")
    recordings_max_age_days: float | None = Field(7.0, gt=0, description="recordings whose data are older are deleted, days (None: no age limit)")
    trends_max_age_days: float | None = Field(
        400.0, gt=0, description="trend rows older than this before their source's newest window are deleted, days "
        "(None: keep all; 2 MB per day of one structure with 5 modes and a window every 30 s, measured)")
    interval_s: float = Field(60.0, gt=0, le=86400, description="how often retention runs, wall-clock s")


@dataclass(frozen=True)
class RecordingFile:
    """One archive file: its path, source, data time of its first message (UNIX s) and size."""

    path: Path
    source: str
    start_s: float
    bytes: int


def list_recordings(directory: str | Path) -> list[RecordingFile]:
    """The archive files in ``directory`` (other files are not the archive's and are left alone),
    oldest first."""
    found = []
    for path in Path(directory).glob("*.mcap"):
        name = parse_archive_name(path)
        if name is None:
            continue
        try:
            size = path.stat().st_size
        except FileNotFoundError:  # deleted meanwhile
            continue
        found.append(RecordingFile(path, name.source, name.start_s, size))
    return sorted(found, key=lambda f: (f.start_s, f.path.name))


def plan_recording_retention(files: Sequence[RecordingFile], *, max_bytes: float, max_age_s: float | None,
                             keep: Sequence[str | Path] = ()) -> list[RecordingFile]:
    """The files to delete so that what stays is within ``max_bytes`` and ``max_age_s``.

    Parameters
    ----------
    files : sequence of RecordingFile
        The archive's files (any order).
    max_bytes : float
        Most bytes the files may take together; the oldest go first.
    max_age_s : float or None
        A file goes once its data end (the next file of its source starts) more than ``max_age_s``
        before the newest file of its source starts. None: no age limit.
    keep : sequence of path
        Files never deleted (the one being written). The newest file of each source is kept too.

    Returns
    -------
    list of RecordingFile
        Oldest first.

    Raises
    ------
    ValueError
        ``max_bytes`` not positive, ``max_age_s`` not positive.
    """
    if not max_bytes > 0:
        raise ValueError(f"{max_bytes=} must be positive")
    if max_age_s is not None and not max_age_s > 0:
        raise ValueError(f"{max_age_s=} must be positive or None")
    ordered = sorted(files, key=lambda f: (f.start_s, f.path.name))
    protected = {Path(p).resolve() for p in keep}
    by_source: dict[str, list[RecordingFile]] = {}
    for f in ordered:
        by_source.setdefault(f.source, []).append(f)
    for group in by_source.values():
        protected.add(group[-1].path.resolve())
    doomed: dict[Path, RecordingFile] = {}
    if max_age_s is not None:
        for group in by_source.values():
            newest = group[-1].start_s
            for f, successor in zip(group, group[1:]):
                if successor.start_s < newest - max_age_s and f.path.resolve() not in protected:
                    doomed[f.path] = f
    total = sum(f.bytes for f in ordered if f.path not in doomed)
    for f in ordered:
        if total <= max_bytes:
            break
        if f.path in doomed or f.path.resolve() in protected:
            continue
        doomed[f.path] = f
        total -= f.bytes
    return [f for f in ordered if f.path in doomed]


class RetentionWorker:
    """Applies ``settings`` to the recordings in ``directory`` (None: no archive) and to the trend
    rows of ``storage``, at start and then every ``settings.interval_s``."""

    def __init__(self, settings: RetentionSettings, *, storage: Any, directory: str | Path | None,
                 current: Any = lambda: None) -> None:
        self.settings = settings
        self.storage = storage
        self.directory = None if directory is None else Path(directory)
        self.current = current  # () -> path(s) of the file(s) being written, or None
        self.files_deleted = 0
        self.bytes_deleted = 0
        self.trend_rows_deleted = 0
        self.errors = 0
        self.runs = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def run_once(self) -> dict[str, int]:
        """One pass; returns what it deleted. Errors are logged and counted, not raised."""
        with self._lock:
            files = self._recordings()
            freed, rows = sum(f.bytes for f in files), 0
            try:
                if self.settings.trends_max_age_days is not None:
                    rows = self.storage.delete_trends_older_than(self.settings.trends_max_age_days * _DAY_S)
            except Exception as exc:  # a locked or closed database must not stop the service
                self.errors += 1
                log.error("trend retention failed: %s", exc)
            self.trend_rows_deleted += rows
            self.runs += 1
            if files or rows:
                log.info("retention: deleted %d recordings (%.1f MB), %d trend rows", len(files), freed / 1e6, rows)
            return {"files": len(files), "bytes": freed, "trend_rows": rows}

    def _recordings(self) -> list[RecordingFile]:
        if self.directory is None or not self.directory.is_dir():
            return []
        s = self.settings
        current = self.current()  # a path, a list of paths (a fleet's files being written), or None
        keep = list(current) if isinstance(current, (list, tuple)) else [current] if current else []
        try:
            plan = plan_recording_retention(
                list_recordings(self.directory), max_bytes=s.recordings_max_gb * 1e9,
                max_age_s=None if s.recordings_max_age_days is None else s.recordings_max_age_days * _DAY_S,
                keep=keep,
            )
        except OSError as exc:
            self.errors += 1
            log.error("recording retention: cannot list %s: %s", self.directory, exc)
            return []
        deleted = []
        for f in plan:
            try:
                f.path.unlink()
            except FileNotFoundError:
                continue
            except OSError as exc:
                self.errors += 1
                log.error("recording retention: cannot delete %s: %s", f.path, exc)
                continue
            deleted.append(f)
            self.files_deleted += 1
            self.bytes_deleted += f.bytes
        return deleted

    def start(self) -> "RetentionWorker":
        self._thread = threading.Thread(target=self._loop, name="retention", daemon=True)
        self._thread.start()
        return self

    def _loop(self) -> None:
        while True:
            self.run_once()
            if self._stop.wait(self.settings.interval_s):
                return

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10.0)

    def status(self) -> dict[str, int]:
        return {"runs": self.runs, "files_deleted": self.files_deleted, "bytes_deleted": self.bytes_deleted,
                "trend_rows_deleted": self.trend_rows_deleted, "errors": self.errors}
