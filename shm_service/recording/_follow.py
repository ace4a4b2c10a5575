"""Incremental reading of a recording: a file still being written (a data logger that calls
``flush()``), or a long file read piece by piece with bounded memory.

``RecordingFollower.poll()`` parses the records that became complete since the last call (the
same parser as ``read_recording``: whole chunks decompressed, payloads decoded a block at a
time) and returns the new accepted samples per topic, after the per-topic time checks
(duplicates and samples stamped before the previous one are skipped and counted).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from collections.abc import Iterable
from typing import Final

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
    ``report.problems``). ``finish()`` salvages the complete messages of a chunk cut off at the
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
    ) -> None:
        self.path = Path(path)
        self._reader = _Reader(self.path, rig, None if topics is None else frozenset(topics), _kinds(kinds))
        self._position = 0
        self._started = False
        self._piece = int(piece_bytes)
        self._last: dict[str, int] = {}
        self.finished = False
        self.damaged = False
        self.bytes_read = 0  # bytes of the file parsed so far (complete records)

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
        return {topic: r.report for topic, r in self._reader.readers.items()}

    def poll(self, max_bytes: int | None = None) -> list[FollowBlock]:
        """Parse what became complete since the last call (at most about ``max_bytes`` of the
        file, default one piece) and return the new samples, one block per topic."""
        if self.finished or self.damaged:
            return []
        budget = self._piece if max_bytes is None else int(max_bytes)
        try:
            with open(self.path, "rb") as f:
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
                f.seek(self._position)
                data = f.read(budget)
                if not data:
                    return []
                # A record longer than the budget: read it whole.
                if len(data) >= 9:
                    _, length = _RECORD_HEAD.unpack_from(data, 0)
                    if 9 + length > len(data) and len(data) == budget:
                        data += f.read(9 + length - len(data))
        except OSError as exc:
            self.report.problems.append(f"{self.path}: cannot read ({exc}); will retry")
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
            self.report.problems.append(
                f"file is damaged near byte {self._position} ({exc!r}); reading stopped"
            )
            consumed = 0
        self._position += consumed
        self.bytes_read = self._position
        reader._flush()
        return self._collect()

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
            self.report.problems.append(f"file is cut off at byte {self._position + len(rest)}: {detail}")
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

