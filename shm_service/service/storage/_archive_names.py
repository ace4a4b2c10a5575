"""The names of the archive's recording files: a file is named after its source and the data time
of its first message, so retention can tell a file's age and source without opening it. The
archive (``stages._archive``) writes these names, retention and ``shm reprocess`` read them back."""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

__all__ = ["ArchiveName", "archive_file_name", "parse_archive_name"]

_STAMP = "%Y%m%dT%H%M%SZ"
_NAME = re.compile(r"^(?P<source>.+)-(?P<start>\d{8}T\d{6}Z)-w\d{8}T\d{6}(?:-\d+)?\.mcap$")


@dataclass(frozen=True)
class ArchiveName:
    """What an archive file's name says: its source and the data time of its first message."""

    source: str
    start_s: float


def archive_file_name(source_id: str, first_ns: int, written: str, n: int = 0) -> str:
    """The file name of ``source_id``'s recording whose first message is at ``first_ns`` (UNIX ns),
    opened at ``written`` (``%Y%m%dT%H%M%S``, UTC); ``n`` > 0 tells apart files of the same name."""
    stamp = datetime.fromtimestamp(first_ns / 1e9, tz=timezone.utc).strftime(_STAMP)
    return f"{source_id}-{stamp}-w{written}" + (f"-{n}" if n else "") + ".mcap"


def parse_archive_name(path: str | Path) -> ArchiveName | None:
    """The source and first data time (UNIX s) of an archive file, or None for any other file."""
    match = _NAME.match(Path(path).name)
    if match is None:
        return None
    start = datetime.strptime(match["start"], _STAMP).replace(tzinfo=timezone.utc)
    return ArchiveName(match["source"], start.timestamp())
