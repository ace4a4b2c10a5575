"""Rotating MCAP recordings of what the service receives and estimates.

Each file is a valid recording of the contract (rig.json attached first, JSON messages, flushed
at least every ``flush_s`` seconds so a crash loses at most that much). A new file starts after
``rotate_mb`` or ``rotate_s`` seconds of data. A file is named after its source and the data
time of its first message (``storage._archive_names``: retention reads it back).
"""

from __future__ import annotations

import logging
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from contract import RigDescription

from ...recording import ESTIMATE_TOPIC, RecordingWriter
from ..storage._archive_names import archive_file_name

__all__ = ["Archive", "ArchiveSettings"]

log = logging.getLogger("shm.serve.archive")


class ArchiveSettings(BaseModel):
    """Rotating MCAP recordings of everything incoming and of the estimates."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    enabled: bool = Field(True, description="write recordings")
    directory: str | None = Field(None, description="where the recordings go (default: DATA_DIR/recordings)")
    raw: Literal["auto", "always", "never"] = Field("auto", description="record incoming samples: auto = not for replay/follow (already a file)")
    estimates: bool = Field(True, description="record /estimate/state")
    estimate_decimation: int = Field(
        4, ge=1, le=200, description="record every n-th estimate [4: 50 Hz of a 200 Hz estimator, Nyquist 25 Hz, three "
        "times mode 6; the raw samples are recorded in full, so the estimates can be recomputed at any rate]")
    rotate_mb: float = Field(256.0, gt=0, description="start a new file after this many MB of (uncompressed) messages")
    rotate_s: float = Field(3600.0, gt=0, description="start a new file after this much data time, s")
    flush_s: float = Field(2.0, gt=0, description="flush (end a chunk) at least this often, wall-clock s")


class Archive:
    def __init__(self, settings: ArchiveSettings, rig: RigDescription, source_id: str,
                 metadata: dict[str, dict[str, str]] | None = None) -> None:
        self.settings = settings
        self.rig = rig
        self.source_id = "".join(c if c.isalnum() or c in "-_." else "_" for c in source_id)
        self.metadata = metadata or {}
        if settings.directory is None:
            raise ValueError("archive.directory is not resolved (load the settings through ServiceSettings)")
        self.directory = Path(settings.directory)
        self._writer: RecordingWriter | None = None
        self._path: Path | None = None
        self._file_start_ns: int | None = None
        self._bytes = 0
        self._last_flush = time.monotonic()
        self.files: list[str] = []
        self.messages = 0
        self.errors = 0

    @property
    def current(self) -> str | None:
        return None if self._path is None else str(self._path)

    def _open(self, first_ns: int) -> RecordingWriter:
        self.directory.mkdir(parents=True, exist_ok=True)
        written = datetime.now(tz=timezone.utc).strftime("%Y%m%dT%H%M%S")
        path = self.directory / archive_file_name(self.source_id, first_ns, written)
        n = 1
        while path.exists():
            path = self.directory / archive_file_name(self.source_id, first_ns, written, n)
            n += 1
        self._writer = RecordingWriter(path, self.rig, metadata=self.metadata)
        self._path = path
        self._file_start_ns = first_ns
        self._bytes = 0
        self.files.append(str(path))
        log.info("recording to %s", path)
        return self._writer

    def _writer_for(self, time_ns: int) -> RecordingWriter:
        s = self.settings
        if self._writer is not None and (
            self._bytes >= s.rotate_mb * 1e6 or time_ns - (self._file_start_ns or time_ns) >= s.rotate_s * 1e9
        ):
            self.close()
        return self._writer or self._open(time_ns)

    def _rotates_at(self) -> int | None:
        """The data time (ns) from which the next file starts (None: no file open)."""
        if self._file_start_ns is None or self._writer is None:
            return None
        return self._file_start_ns + int(self.settings.rotate_s * 1e9)

    def write_many(self, messages: list[tuple[str, int, bytes, int]]) -> None:
        """Write (topic, log_time_ns, payload, publish_time_ns) messages; a file holds at most
        ``rotate_s`` of data however many seconds one call brings."""
        if not messages:
            return
        try:
            writer = self._writer_for(messages[0][1])
            rotates_at = self._rotates_at()
            size = 0
            for topic, log_ns, payload, pub_ns in messages:
                if rotates_at is not None and log_ns >= rotates_at:
                    self._bytes += size
                    size = 0
                    writer = self._writer_for(log_ns)
                    rotates_at = self._rotates_at()
                writer.write(topic, log_ns, payload, pub_ns)
                size += len(payload) + 40
            self._bytes += size
            self.messages += len(messages)
        except (OSError, ValueError) as exc:
            self.errors += 1
            log.error("recording failed: %s", exc)

    def write_estimates(self, stamps_ns: Any, payloads: list[bytes]) -> None:
        """Write estimate payloads (encoded JSON) stamped ``stamps_ns`` (integer ns, in order; log
        and publish time), each file's part at once."""
        if not len(payloads):
            return
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        try:
            lo = 0
            while lo < len(stamps):
                writer = self._writer_for(int(stamps[lo]))
                rotates_at = self._rotates_at()
                hi = len(stamps) if rotates_at is None else max(lo + 1, int(np.searchsorted(stamps, rotates_at)))
                part = payloads[lo:hi]
                writer.write_batch(ESTIMATE_TOPIC, stamps[lo:hi], part)
                self._bytes += sum(map(len, part)) + 40 * len(part)
                self.messages += len(part)
                lo = hi
        except (OSError, ValueError) as exc:
            self.errors += 1
            log.error("recording failed: %s", exc)

    def maybe_flush(self, force: bool = False) -> None:
        if self._writer is None:
            return
        now = time.monotonic()
        if force or now - self._last_flush >= self.settings.flush_s:
            try:
                self._writer.flush()
            except (OSError, ValueError) as exc:
                self.errors += 1
                log.error("recording flush failed: %s", exc)
            self._last_flush = now

    def close(self) -> None:
        if self._writer is not None:
            try:
                self._writer.close()
            except (OSError, ValueError) as exc:
                self.errors += 1
                log.error("closing the recording failed: %s", exc)
            self._writer = None

    def status(self) -> dict[str, Any]:
        return {"directory": str(self.directory), "current": self.current, "files": len(self.files),
                "messages": self.messages, "errors": self.errors}
