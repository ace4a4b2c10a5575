"""Incremental reading of a recording: a file still being written (a data logger that calls
``flush()``), or a long file read piece by piece with bounded memory.

``RecordingFollower.poll()`` parses the records that became complete since the last call (the
same parser as ``read_recording``: whole chunks decompressed, payloads decoded a block at a
time) and returns the new accepted samples per topic, after the per-topic time checks
(duplicates and samples stamped before the previous one are skipped and counted).

The path is what is followed, not one open file: a file replaced under the same name (a new
inode, as ``mv``/``os.replace`` or delete-and-create leave; a file shorter than what was read; a
different start, as a rewrite in place leaves) is noticed at the next poll and read from its
start, its samples judged against the times already returned (a rewrite of what was read is
counted as duplicates, a continuation is taken). A file that is missing (not there yet, or
deleted) is waited for, and reported once with a count, not once per poll.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from collections.abc import Iterable
from typing import Any, Final

import numpy as np

from contract import Kind, RigDescription

from ._reader import (
    _RECORD_HEAD,
    ReadReport,
    RecordingError,
    TopicReport,
    _Reader,
    _kinds,
    _Stop,
)
from ._writer import MAGIC

__all__ = ["FollowBlock", "RecordingFollower"]

_PIECE: Final = 16 << 20  # bytes read per step (a chunk record is about 1 MiB uncompressed)
_HEAD: Final = 4096  # bytes of the file's start compared at each poll (a rewrite in place changes them)


@dataclass(frozen=True, eq=False)
class FollowBlock:
    """New accepted samples of one topic: ``log_time_ns`` (int64, strictly increasing, and after
    every sample of the topic returned before), ``publish_time_ns`` and ``values`` (n, k)."""

    topic: str
    kind: str
    name: str
    log_time_ns: np.ndarray
    publish_time_ns: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.log_time_ns)


class RecordingFollower:
    """Reads ``path`` incrementally. ``topics`` (or ``kinds``, as for ``read_recording``) limits
    decoding (others are counted, not decoded).

    ``poll()`` returns the new blocks; ``finished`` is set once the data section ended (the
    writer closed the file); ``damaged`` once the file cannot be read further (a problem is in
    ``report.problems``); ``missing`` while the path does not exist; ``replaced`` counts the
    files read from their start after a replacement. ``reopen_finished=True`` keeps watching a
    finished file for a replacement (``poll`` then returns the new file's samples). ``finish()`` salvages the complete messages of a chunk cut off at the
    end of a file that will not grow any more (a crashed writer) and marks it finished.
    Raises ``RecordingError`` for a missing or invalid rig description or a topic with the wrong
    schema, like ``read_recording``.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        rig: RigDescription | str | Path | None = None,
        topics: frozenset[str] | set[str] | None = None,
        kinds: Iterable[Kind] | None = None,
        piece_bytes: int = _PIECE,
        reopen_finished: bool = False,
    ) -> None:
        self.path = Path(path)
        self._options = (rig, None if topics is None else frozenset(topics), _kinds(kinds))
        self._reader = _Reader(self.path, *self._options)
        self._position = 0
        self._started = False
        self._piece = int(piece_bytes)
        self._last: dict[str, int] = {}
        self._identity: tuple[int, int] | None = None  # (device, inode) of the file being read
        self._head = b""  # its first bytes as read
        self._problem_counts: dict[str, int] = {}
        self._reopen_finished = reopen_finished
        self.finished = False
        self.damaged = False
        self.missing = False
        self.replaced = 0
        self.bytes_read = 0  # bytes of the file parsed so far (complete records)
        self._earlier: dict[str, dict[str, Any]] = {}  # counts of the files read before a replacement

    # -- public ---------------------------------------------------------------------------------

    @property
    def report(self) -> ReadReport:
        return self._reader.report

    @property
    def rig(self) -> RigDescription | None:
        """The rig description, once the ``rig.json`` attachment (or ``rig=``) is known."""
        reader = self._reader
        if reader.rig is None and reader.rig_json is not None:
            return reader._require_rig()
        return reader.rig

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        return self._reader.metadata

    @property
    def topic_reports(self) -> dict[str, TopicReport]:
        """Per-topic counters, summed over the files read (a replaced file's included)."""
        out = {topic: r.report for topic, r in self._reader.readers.items()}
        for topic, counts in self._earlier.items():
            current = out.get(topic)
            merged = replace(current) if current is not None else TopicReport(topic=topic, schema=counts.get("schema", ""))
            for name, value in counts.items():
                if name != "schema":
                    setattr(merged, name, getattr(merged, name) + value)
            out[topic] = merged
        return out

    def poll(self, max_bytes: int | None = None) -> list[FollowBlock]:
        """Parse what became complete since the last call (at most about ``max_bytes`` of the
        file, default one piece) and return the new samples, one block per topic."""
        if self.damaged and not self._reopen_finished:
            return []
        if self.finished and not self._reopen_finished:
            return []
        budget = self._piece if max_bytes is None else int(max_bytes)
        try:
            with open(self.path, "rb") as f:
                if self.missing:
                    self.missing = False
                    self._note(f"{self.path}: the file is there again")
                stat = os.fstat(f.fileno())
                if self._identity is not None and self._was_replaced(f, stat):
                    self._restart()
                    f.seek(0)
                if self.finished or self.damaged:
                    return []
                if not self._started:
                    head = f.read(len(MAGIC))
                    if len(head) < len(MAGIC):
                        if not MAGIC.startswith(head):
                            raise RecordingError(f"{self.path}: not an MCAP file (starts with {head!r})")
                        return []
                    if head != MAGIC:
                        raise RecordingError(f"{self.path}: not an MCAP file (starts with {head!r})")
                    self._started = True
                    self._position = len(MAGIC)
                    self._identity = (stat.st_dev, stat.st_ino)
                f.seek(self._position)
                data = f.read(budget)
                if len(self._head) < _HEAD and self._position + len(data) > len(self._head):
                    f.seek(0)
                    self._head = f.read(min(_HEAD, self._position + len(data)))
                if not data:
                    return []
                # A record longer than the budget: read it whole.
                if len(data) >= 9:
                    _, length = _RECORD_HEAD.unpack_from(data, 0)
                    if 9 + length > len(data) and len(data) == budget:
                        f.seek(self._position + len(data))
                        data += f.read(9 + length - len(data))
        except FileNotFoundError:
            if not self.missing:
                self.missing = True
            self._note(f"{self.path}: the file does not exist (not yet written, or deleted); waiting for it")
            return []
        except OSError as exc:
            self._note(f"{self.path}: cannot read ({type(exc).__name__}: {exc.strerror or exc}); will retry")
            return []
        reader = self._reader
        try:
            consumed = reader._scan(data, 0, len(data))
        except _Stop:
            self.finished = True
            consumed = len(data)
        except RecordingError:
            raise
        except Exception as exc:  # damage in the middle of the file
            self.damaged = True
            self._note(f"file is damaged near byte {self._position} ({exc!r}); reading stopped")
            consumed = 0
        self._position += consumed
        self.bytes_read = self._position
        reader._flush()
        return self._collect()

    def _was_replaced(self, f: Any, stat: os.stat_result) -> str | None:
        """Why the file at the path is not the one read so far (None: it is)."""
        why = None
        if (stat.st_dev, stat.st_ino) != self._identity:
            why = "a new file (another inode)"
        elif stat.st_size < self._position:
            why = f"shorter ({stat.st_size} bytes) than what was read ({self._position} bytes)"
        elif self._head:
            f.seek(0)
            if f.read(len(self._head)) != self._head:
                why = "rewritten (its start differs)"
        if why is not None:
            self._note(f"{self.path} was replaced: {why}; reading the new file from its start")
        return why

    def _restart(self) -> None:
        """Read the path from its start again; the times already returned stay the reference
        (what the new file repeats is counted as duplicates, never returned twice)."""
        for topic, r in self._reader.readers.items():
            total = self._earlier.setdefault(topic, {"schema": r.report.schema})
            for name in ("messages", "accepted", "duplicate", "backwards", "malformed", "nonfinite"):
                total[name] = total.get(name, 0) + getattr(r.report, name)
        problems = self._reader.report.problems
        rig = self._reader.rig
        self._reader = _Reader(self.path, rig if rig is not None else self._options[0], *self._options[1:])
        self._reader.report.problems = problems
        self._position = 0
        self._started = False
        self._identity = None
        self._head = b""
        self.finished = False
        self.damaged = False
        self.replaced += 1

    def _note(self, problem: str) -> None:
        """Add ``problem`` to the report once; a repeat counts (``... (seen 12 times)``)."""
        problems = self.report.problems
        n = self._problem_counts.get(problem, 0) + 1
        self._problem_counts[problem] = n
        if n == 1:
            problems.append(problem)
            return
        label = f"{problem} (seen {n} times)"
        previous = problem if n == 2 else f"{problem} (seen {n - 1} times)"
        for i in range(len(problems) - 1, -1, -1):
            if problems[i] == previous:
                del problems[i]
                break
        problems.append(label)

    def finish(self) -> list[FollowBlock]:
        """The file will not grow: read what is left, salvage a cut-off chunk, and stop."""
        blocks: list[FollowBlock] = []
        while not (self.finished or self.damaged):
            before = self._position
            blocks.extend(self.poll())
            if self._position == before:
                break
        if not (self.finished or self.damaged):
            self.report.truncated = True
            try:
                with open(self.path, "rb") as f:
                    f.seek(self._position)
                    rest = f.read()
            except OSError:
                rest = b""
            detail = self._reader._describe_cut(rest, 0, len(rest), self._position)
            self._note(f"file is cut off at byte {self._position + len(rest)}: {detail}")
            self._reader._flush()
            blocks.extend(self._collect())
        self.finished = True
        return blocks

    # -- internals ------------------------------------------------------------------------------

    def _collect(self) -> list[FollowBlock]:
        out: list[FollowBlock] = []
        for topic, channel in self._reader.readers.items():
            if not channel.decode or not channel.blocks:
                channel.blocks.clear()
                continue
            blocks = channel.blocks
            times = np.concatenate([b[0] for b in blocks])
            publish = np.concatenate([b[1] for b in blocks])
            width = sum(1 if s == 0 else (s or 0) for s in channel.sizes)
            parts = [b[2].reshape(len(b[2]), -1) for b in blocks if len(b[2])]
            values = np.concatenate(parts) if parts else np.empty((0, width))
            blocks.clear()
            if not len(times):
                continue
            previous = np.empty_like(times)
            previous[0] = self._last.get(topic, np.iinfo(np.int64).min)
            np.maximum.accumulate(np.concatenate([[previous[0]], times[:-1]]), out=previous)
            accept = times > previous
            report = channel.report
            report.duplicate += int(np.count_nonzero(times == previous))
            report.backwards += int(np.count_nonzero(times < previous))
            if not accept.all():
                times, publish, values = times[accept], publish[accept], values[accept]
            if not len(times):
                continue
            report.accepted += len(times)
            self._last[topic] = int(times[-1])
            out.append(FollowBlock(topic, channel.info.kind, channel.name, times, publish, values))
        return out

