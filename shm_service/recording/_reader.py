"""Reading recordings: the one reader of the recording contract for everything downstream.

The file is parsed here (chunks decompressed whole), not with ``mcap.reader``: the library needs
the footer, which a file cut off mid-write lacks, and iterates at about 150 k messages/s. A
compiled scan (``_fastdecode``) lists the message records of each chunk; payloads are decoded a
chunk and a channel at a time by the compiled template decoder (the contract's fixed payload
layouts, exact float parsing), and only what it does not decide (NaN, a missing key, other
layouts, ...) goes the reference way: orjson objects for the block, else message by message
to count and skip exactly the bad ones.
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from collections import Counter
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Final, cast, get_args

import lz4.frame
import numpy as np
import orjson
import zstandard

from contract import (
    NOMINAL_PERIOD_NS,
    payload_fields,
    Kind,
    RigDescription,
    RigError,
    TopicInfo,
    classify_topic,
    load_rig,
    parse_rig,
)

from ._plausibility import ValueLimits, all_plausible, implausible_values
from ._writer import MAGIC, RIG_ATTACHMENT

__all__ = ["Channel", "ReadReport", "Recording", "RecordingError", "TopicReport", "read_recording"]

#: A sensor whose last sample is more than this before the recording's end has gone silent (ns).
SILENT_AFTER_NS: Final = 1_000_000_000
#: A time step longer than this many nominal periods is a gap.
GAP_FACTOR: Final = 1.5

#: What a sensor of each kind can read (``shm serve``'s default ``source.limits``): beyond is implausible.
_LIMITS: Final = ValueLimits()
_SENSOR_KINDS: Final = frozenset({"imu", "tof", "strain", "bearing", "temperature"})

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_ATTACHMENT, _OP_METADATA, _OP_DATA_END = 9, 12, 15
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # record head + channel id, sequence, log time, publish time
_MESSAGE_BODY_HEAD: Final = _MESSAGE_HEAD.size - _RECORD_HEAD.size
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length


class RecordingError(ValueError):
    """A recording that breaks the contract in a way the reader refuses (names the key or topic)."""


@dataclass
class TopicReport:
    """Counters of one topic. ``messages`` is what the file holds; ``accepted`` what was kept;
    the rest are the skipped messages by reason. ``gaps`` counts time steps longer than 1.5
    nominal periods and ``missing_samples`` the samples they lack; ``silent_after_s`` is set
    when the topic's last sample is more than 1 s before the recording's end (s from its start).
    """

    topic: str
    schema: str
    messages: int = 0
    accepted: int = 0
    malformed: int = 0
    nonfinite: int = 0
    implausible: int = 0
    duplicate: int = 0
    backwards: int = 0
    gaps: int = 0
    missing_samples: int = 0
    silent_after_s: float | None = None

    @property
    def rejected(self) -> int:
        return self.malformed + self.nonfinite + self.implausible + self.duplicate + self.backwards


@dataclass
class ReadReport:
    """What reading found: per-topic counters, the topics skipped (with their message counts),
    whether the file was cut off, and human-readable problems."""

    topics: dict[str, TopicReport] = field(default_factory=dict)
    skipped_topics: dict[str, int] = field(default_factory=dict)
    truncated: bool = False
    problems: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {
            "topics": {topic: asdict(report) for topic, report in self.topics.items()},
            "skipped_topics": dict(self.skipped_topics),
            "truncated": self.truncated,
            "problems": list(self.problems),
        }


@dataclass(frozen=True, eq=False)
class Channel:
    """The accepted samples of one topic, in strictly increasing ``log_time_ns`` (ns).

    ``values`` has one row per sample laid out as ``fields`` (vector payload keys expand to
    ``name[i]``): imu accel (m/s²) then gyro (rad/s); tof/bearing distance (m); strain (m/m);
    temperature (°C); truth d, h, phi, e, deflection..., curvature...; estimate d, h, phi, e,
    b..., deflection..., curvature..., covariance_diagonal....
    """

    topic: str
    kind: Kind
    name: str
    position: float | None
    fields: tuple[str, ...]
    log_time_ns: np.ndarray
    publish_time_ns: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.log_time_ns)

    def time_s(self, start_ns: int) -> np.ndarray:
        """Sample times in s after ``start_ns`` (ns)."""
        return (self.log_time_ns - start_ns) / 1e9


@dataclass(frozen=True, eq=False)
class Recording:
    """A recording read against the contract. ``start_ns``/``end_ns`` (ns) span the samples of
    all contract channels (0 when there are none)."""

    path: Path
    rig: RigDescription
    channels: dict[str, Channel]
    metadata: dict[str, dict[str, str]]
    attachments: tuple[str, ...]
    report: ReadReport
    start_ns: int
    end_ns: int

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9

    def merged(self, topics: Iterable[str] | None = None) -> Iterator[tuple[int, str, np.ndarray]]:
        """Yield ``(log_time_ns, topic, row)`` over the channels (all, or ``topics``) in log-time
        order; equal times come in topic-name order."""
        names = sorted(self.channels if topics is None else set(topics))
        for name in names:
            if name not in self.channels:
                raise KeyError(f"topic {name!r} is not in the recording (has {sorted(self.channels)})")
        chosen = [self.channels[name] for name in names]
        if not chosen:
            return
        times = np.concatenate([c.log_time_ns for c in chosen])
        which = np.repeat(np.arange(len(chosen)), [len(c) for c in chosen])
        rows = np.concatenate([np.arange(len(c)) for c in chosen])
        order = np.argsort(times, kind="stable")
        for time, index, row in zip(times[order].tolist(), which[order].tolist(), rows[order].tolist()):
            yield time, names[index], chosen[index].values[row]


def read_recording(
    path: str | Path,
    *,
    rig: RigDescription | str | Path | None = None,
    topics: Iterable[str] | None = None,
    kinds: Iterable[Kind] | None = None,
) -> Recording:
    """Read the recording at ``path``, keeping what is valid and reporting what is not.

    ``rig`` replaces the file's ``rig.json`` attachment (a description, or a ``.json``/``.toml``
    file). ``topics`` limits decoding to those topics, ``kinds`` to the topics of those kinds
    ("imu", "tof", "strain", "bearing", "temperature", "truth", "estimate"). A file cut off mid-write yields every
    complete message before the damage (``report.truncated``). Raises ``RecordingError`` for a
    missing or invalid rig description and for a contract topic with the wrong encoding or schema.
    """
    return _Reader(Path(path), rig, None if topics is None else frozenset(topics), _kinds(kinds)).read()


def _kinds(kinds: Iterable[str] | None) -> frozenset[str] | None:
    if kinds is None:
        return None
    chosen = frozenset(kinds)
    unknown = chosen - set(get_args(Kind))
    if unknown:
        raise ValueError(f"kinds={sorted(chosen)}: unknown kind(s) {sorted(unknown)}")
    return chosen


class _ChannelReader:
    """Collects one topic's messages and decodes them a block (a chunk's worth) at a time.

    Pending messages are kept as spans of the buffer they came in (a decompressed chunk), not
    as one bytes object each; ``flush`` decodes a block with the compiled template decoder and
    hands only what it could not decode to the reference path (orjson, then the stdlib)."""

    def __init__(self, topic: str, info: TopicInfo, name: str, position: float | None, stations: int, decode: bool,
                 biaxial: bool = False) -> None:
        self.topic = topic
        self.info = info
        self.name = name
        self.position = position
        self.decode = decode
        # a biaxial beam's truth and estimates carry the ξ plane's keys after the planar ones
        self.fields = payload_fields(info.title, biaxial=biaxial)
        self.sizes: list[int | None] = [
            stations if f.size == "stations" else None if f.size == "free" else f.size for f in self.fields
        ]
        # A number, not a vector: a rig without truth stations makes a vector of size 0 too (an empty list).
        self.scalar: list[bool] = [f.size == 0 for f in self.fields]
        # pending pieces: (buffer, log times, publish times, payload starts, payload stops)
        self.pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self.pending = 0
        self.times: np.ndarray = _NO_TIMES  # log times of the block being decoded (for reports)
        self.payloads: list[bytes] = []  # the payloads the reference path decodes
        self.blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.report = TopicReport(topic, info.title)
        self.first_malformed: tuple[int, str] | None = None
        self.first_nonfinite: int | None = None
        self.first_implausible: int | None = None
        self.raw_min: int | None = None
        self.raw_max: int | None = None
        self._template: np.ndarray | None = None
        self._width = 0

    def add(self, buf: np.ndarray, times: np.ndarray, publish: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> None:
        """Queue messages: their times and the spans of their payloads in ``buf`` (uint8)."""
        self.pieces.append((buf, times, publish, starts, stops))
        self.pending += len(times)

    def flush(self) -> None:
        """Decode the pending messages into a block of valid rows."""
        count = self.pending
        if count == 0:
            return
        pieces, self.pieces, self.pending = self.pieces, [], 0
        self.report.messages += count
        times = np.concatenate([p[1] for p in pieces]) if len(pieces) > 1 else pieces[0][1]
        if not self.decode:
            low, high = int(times.min()), int(times.max())
            self.raw_min = low if self.raw_min is None else min(self.raw_min, low)
            self.raw_max = high if self.raw_max is None else max(self.raw_max, high)
            return
        publish = np.concatenate([p[2] for p in pieces]) if len(pieces) > 1 else pieces[0][2]
        template = self._template_codes()
        if template is None:
            values, keep = self._decode_reference(pieces, times, None)
        else:
            from ._fastdecode import decode_template  # compiled (numba): loaded when a recording is decoded

            parts = [decode_template(buf, starts, stops, template, self._width) for buf, _, _, starts, stops in pieces]
            values = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
            decoded = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
            if decoded.all():
                keep = None
            else:  # what the template does not cover goes the reference way, in place
                missing = ~decoded
                rows, kept = self._decode_reference(pieces, times, missing)
                keep = decoded.copy()
                keep[missing] = kept
                values[np.flatnonzero(missing)[kept]] = rows
                values = values[keep]
        if keep is not None:
            times, publish = times[keep], publish[keep]
        self.blocks.append((times, publish, values))

    def _template_codes(self) -> np.ndarray | None:
        """The payload skeleton of this schema once every vector size is known."""
        if self._template is None and None not in self.sizes:
            example = orjson.dumps({f.name: 0 if scalar else [0] * size
                                    for f, size, scalar in zip(self.fields, cast("list[int]", self.sizes), self.scalar)})
            self._width = example.count(b"0")
            from ._fastdecode import template_codes

            self._template = template_codes(example.replace(b"0", b"#"))
        return self._template

    def _decode_reference(self, pieces, times: np.ndarray, select: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Rows and kept mask of the pending messages (those of ``select``) by orjson objects,
        else message by message."""
        payloads: list[bytes] = []
        for buf, _, _, starts, stops in pieces:
            data = buf.tobytes() if len(starts) > 64 else None
            for a, b in zip(starts.tolist(), stops.tolist()):
                payloads.append(data[a:b] if data is not None else buf[a:b].tobytes())
        if select is not None:
            payloads = [payloads[i] for i in np.flatnonzero(select).tolist()]
            times = times[select]
        self.payloads, self.times = payloads, times
        try:
            values = self._decode_fast()
            if values is not None:
                return values, np.ones(len(payloads), dtype=bool)
            return self._decode_slow()
        finally:
            self.payloads, self.times = [], _NO_TIMES

    def _decode_fast(self) -> np.ndarray | None:
        """All pending payloads as rows, or ``None`` if any of them needs a closer look."""
        payloads = self.payloads
        joined = b"\n".join(payloads)
        if b"true" in joined or b"false" in joined:  # numpy would turn booleans into numbers
            return None
        count = len(payloads)
        loads = orjson.loads
        sizes = list(self.sizes)
        columns = []
        try:
            objects = [loads(p) for p in payloads]
            for index, spec in enumerate(self.fields):
                name = spec.name
                column = np.array([o[name] for o in objects])
                if column.dtype.kind not in "fiu":
                    return None
                size = sizes[index]
                if size is None and column.ndim == 2:
                    size = sizes[index] = column.shape[1]
                if column.shape != ((count,) if self.scalar[index] else (count, size)):
                    return None
                columns.append(column.reshape(count, -1))
        except (orjson.JSONDecodeError, KeyError, TypeError, ValueError, IndexError):
            return None
        values = np.concatenate(columns, axis=1, dtype=np.float64)
        if not np.isfinite(values).all():  # integers beyond the float range
            return None
        self.sizes = sizes
        return values

    def _decode_slow(self) -> tuple[np.ndarray, np.ndarray]:
        """Decode message by message; returns the valid rows and the mask of kept messages."""
        rows: list[list[float]] = []
        keep = np.zeros(len(self.payloads), dtype=bool)
        for index, payload in enumerate(self.payloads):
            try:
                row = self._row(_loads_lenient(payload))
            except _Malformed as exc:
                self.report.malformed += 1
                if self.first_malformed is None:
                    self.first_malformed = (int(self.times[index]), str(exc))
                continue
            if not all(map(math.isfinite, row)):
                self.report.nonfinite += 1
                if self.first_nonfinite is None:
                    self.first_nonfinite = int(self.times[index])
                continue
            rows.append(row)
            keep[index] = True
        width = sum(1 if scalar else (s or 0) for s, scalar in zip(self.sizes, self.scalar))
        return np.array(rows, dtype=np.float64).reshape(len(rows), width), keep

    def _row(self, payload: Any) -> list[float]:
        if not isinstance(payload, dict):
            raise _Malformed(f"payload is a JSON {type(payload).__name__}, expected an object")
        row: list[float] = []
        for index, spec in enumerate(self.fields):
            if spec.name not in payload:
                raise _Malformed(f"missing key {spec.name!r}")
            value = payload[spec.name]
            size = self.sizes[index]
            if self.scalar[index]:
                row.append(_number(spec.name, value))
                continue
            if not isinstance(value, list):
                raise _Malformed(f"{spec.name!r} is {_describe(value)}, expected a list of numbers")
            if size is not None and len(value) != size:
                raise _Malformed(f"{spec.name!r} has {len(value)} values, expected {size}")
            row.extend(_number(f"{spec.name}[{i}]", v) for i, v in enumerate(value))
        for index, spec in enumerate(self.fields):  # a valid message fixes the free lengths
            if self.sizes[index] is None:
                self.sizes[index] = len(payload[spec.name])
        return row

    def field_names(self) -> tuple[str, ...]:
        names: list[str] = []
        for spec, size, scalar in zip(self.fields, self.sizes, self.scalar):
            names.extend([spec.name] if scalar else [f"{spec.name}[{i}]" for i in range(size or 0)])
        return tuple(names)

    def finish(self, width: int, limits: ValueLimits) -> Channel:
        """The channel of accepted samples: time checks (duplicates, backwards) and gap counts."""
        report = self.report
        if self.blocks:
            times = np.concatenate([b[0] for b in self.blocks])
            publish = np.concatenate([b[1] for b in self.blocks])
            values = np.concatenate([b[2].reshape(len(b[2]), -1) for b in self.blocks if len(b[2])] or [np.empty((0, width))])
        else:
            times = publish = np.empty(0, dtype=np.int64)
            values = np.empty((0, width))
        if len(times) and self.info.kind in _SENSOR_KINDS and not all_plausible(self.info.kind, values, limits):
            # a value no sensor of this kind can read (a DAQ's overflow code, a corrupted float)
            beyond = implausible_values(self.info.kind, values, limits)
            report.implausible = int(np.count_nonzero(beyond))
            self.first_implausible = int(times[np.argmax(beyond)])
            times, publish, values = times[~beyond], publish[~beyond], values[~beyond]
        if len(times):
            previous = np.empty_like(times)
            previous[0] = np.iinfo(np.int64).min
            np.maximum.accumulate(times[:-1], out=previous[1:])
            accept = times > previous
            report.duplicate = int(np.count_nonzero(times == previous))
            report.backwards = int(np.count_nonzero(times < previous))
            times, publish, values = times[accept], publish[accept], values[accept]
        report.accepted = len(times)
        period = NOMINAL_PERIOD_NS.get(self.info.kind)
        if period is not None and len(times) > 1:
            steps = np.diff(times)
            long_steps = steps[steps > GAP_FACTOR * period]
            report.gaps = len(long_steps)
            report.missing_samples = int(np.sum(np.rint(long_steps / period).astype(np.int64) - 1))
        for array in (times, publish, values):
            array.flags.writeable = False
        return Channel(self.topic, self.info.kind, self.name, self.position, self.field_names(), times, publish, values)


_NO_TIMES: Final = np.empty(0, dtype=np.int64)


class _Malformed(ValueError):
    """A payload that does not follow its schema (the message says how)."""


def _loads_lenient(payload: bytes) -> Any:
    """orjson, falling back to the stdlib for what orjson refuses (``NaN``, ``Infinity``)."""
    try:
        return orjson.loads(payload)
    except orjson.JSONDecodeError:
        try:
            return json.loads(payload)
        except (ValueError, RecursionError) as exc:
            raise _Malformed(f"not JSON: {exc}") from None


def _describe(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 40 else text[:37] + '...'}"


def _number(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Malformed(f"{name!r} is {_describe(value)}, expected a number")
    try:
        return float(value)
    except OverflowError:
        return math.inf


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(buf, pos)
    end = pos + 4 + length
    if end > len(buf):
        raise struct.error(f"string of {length} bytes runs past the record")
    return bytes(buf[pos + 4 : end]).decode("utf-8"), end


def _string_map(buf: bytes, pos: int) -> dict[str, str]:
    (length,) = _U32.unpack_from(buf, pos)
    pos += 4
    end = pos + length
    result: dict[str, str] = {}
    while pos < end:
        key, pos = _string(buf, pos)
        result[key], pos = _string(buf, pos)
    return result


class _Stop(Exception):
    """The data section ended (DataEnd or Footer)."""


class _Reader:
    def __init__(self, path: Path, rig: RigDescription | str | Path | None, topics: frozenset[str] | None,
                 kinds: frozenset[str] | None = None) -> None:
        self.path = path
        self.topics = topics
        self.kinds = kinds
        self.rig: RigDescription | None = None
        if isinstance(rig, RigDescription):
            self.rig = rig
        elif rig is not None:
            try:
                self.rig = load_rig(rig)
            except RigError as exc:
                raise RecordingError(str(exc)) from None
        self.rig_json: bytes | None = None
        self.schemas: dict[int, tuple[str, str]] = {}
        self.channel_topics: dict[int, str] = {}
        self.routes: dict[int, _ChannelReader] = {}
        self.readers: dict[str, _ChannelReader] = {}
        self.skipped: dict[int, tuple[str, str]] = {}
        self.unrouted: Counter[int] = Counter()
        self.attachments: list[str] = []
        self.metadata: dict[str, dict[str, str]] = {}
        self.report = ReadReport()

    # -- parsing ------------------------------------------------------------------------------

    def read(self) -> Recording:
        data = self.path.read_bytes()
        report = self.report
        if not data.startswith(MAGIC):
            if not MAGIC.startswith(data):
                raise RecordingError(f"{self.path}: not an MCAP file (starts with {data[:8]!r})")
            report.truncated = True
            report.problems.append(f"file is cut off inside the MCAP magic ({len(data)} bytes)")
        else:
            self._read_data_section(data)
        for reader in self.readers.values():
            reader.flush()
        return self._assemble()

    def _read_data_section(self, data: bytes) -> None:
        size = len(data)
        position = len(MAGIC)
        try:
            position = self._scan(data, position, size)
        except _Stop:
            return
        except RecordingError:
            raise
        except Exception as exc:  # damage: keep what was read before it
            self.report.truncated = True
            self.report.problems.append(f"file is damaged near byte {position} of {size}: {exc!r}; reading stopped")
            return
        self.report.truncated = True
        self.report.problems.append(f"file is cut off at byte {size}: {self._describe_cut(data, position, size)}")

    def _describe_cut(self, data: bytes, position: int, size: int, offset: int = 0) -> str:
        """What stops the data at ``position`` of ``data[:size]`` (``data`` starts at byte ``offset``
        of the file); salvages the complete messages of a partly written chunk."""
        if position >= size:
            return "no DataEnd record (the writer did not finish)"
        detail = f"the record at byte {offset + position} is incomplete"
        try:
            opcode, _ = _RECORD_HEAD.unpack_from(data, position)
            if opcode == _OP_CHUNK:
                salvaged = self._salvage_chunk(data, position + _RECORD_HEAD.size)
                detail += f" (a chunk; {salvaged} complete messages recovered from it)"
        except RecordingError:
            raise
        except Exception as exc:
            detail += f" ({exc!r})"
        return detail

    def _scan(self, buf: bytes, pos: int, end: int) -> int:
        """Parse the records in ``buf[pos:end]``; returns where an incomplete record starts (or
        ``end``). Raises ``_Stop`` at the end of the data section."""
        from ._fastdecode import scan_buffer  # compiled (numba): loaded when a recording is read

        data = np.frombuffer(buf, dtype=np.uint8)
        while True:
            n, pos, state, cids, logs, pubs, starts, stops = scan_buffer(data, pos, end)
            if n:
                self._route(data, cids, logs, pubs, starts, stops)
            if state == 1:  # a record the reader handles here
                opcode, length = _RECORD_HEAD.unpack_from(buf, pos)
                following = pos + 9 + length
                self._record(opcode, buf, pos + 9, following)
                pos = following
            elif state != 3:  # at the end, or at an incomplete record
                return pos

    def _route(self, data: np.ndarray, cids: np.ndarray, logs: np.ndarray, pubs: np.ndarray, starts: np.ndarray,
               stops: np.ndarray) -> None:
        """Hand the scanned messages to their channels' readers (file order kept per channel)."""
        routes = self.routes
        groups: list[tuple[int, np.ndarray | None]]
        if cids[0] == cids[-1] and (cids == cids[0]).all():
            groups = [(int(cids[0]), None)]
        else:
            order = np.argsort(cids, kind="stable")
            ordered = cids[order]
            bounds = [0, *(np.flatnonzero(ordered[1:] != ordered[:-1]) + 1).tolist(), len(order)]
            groups = [(int(ordered[a]), order[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
        for channel_id, index in groups:
            reader = routes.get(channel_id)
            count = len(cids) if index is None else len(index)
            if reader is None:
                self.unrouted[channel_id] += count
            elif index is None:
                reader.add(data, logs, pubs, starts, stops)
            else:
                reader.add(data, logs[index], pubs[index], starts[index], stops[index])

    def _record(self, opcode: int, buf: bytes, body: int, end: int) -> None:
        if opcode == _OP_CHUNK:
            self._chunk(buf, body, end)
        elif opcode == _OP_SCHEMA:
            (schema_id,) = _U16.unpack_from(buf, body)
            name, pos = _string(buf, body + 2)
            encoding, _ = _string(buf, pos)
            self.schemas.setdefault(schema_id, (name, encoding))
        elif opcode == _OP_CHANNEL:
            self._channel(buf, body)
        elif opcode == _OP_ATTACHMENT:
            name, pos = _string(buf, body + 16)
            _, pos = _string(buf, pos)
            (length,) = _U64.unpack_from(buf, pos)
            self.attachments.append(name)
            if name == RIG_ATTACHMENT and self.rig_json is None:
                self.rig_json = bytes(buf[pos + 8 : pos + 8 + length])
        elif opcode == _OP_METADATA:
            name, pos = _string(buf, body)
            self.metadata.setdefault(name, {}).update(_string_map(buf, pos))
        elif opcode == _OP_MESSAGE:
            self.report.problems.append(f"message record of {end - body} bytes is too short; skipped")
        elif opcode in (_OP_DATA_END, _OP_FOOTER):
            raise _Stop
        # Header, indexes, statistics and unknown records carry nothing the reader needs.

    def _chunk(self, buf: bytes, body: int, end: int) -> None:
        _, _, size, crc, name_length = _CHUNK_HEAD.unpack_from(buf, body)
        pos = body + _CHUNK_HEAD.size
        compression = bytes(buf[pos : pos + name_length]).decode("utf-8")
        (length,) = _U64.unpack_from(buf, pos + name_length)
        pos += name_length + 8
        compressed = buf[pos : min(pos + length, end)]
        try:
            if compression == "zstd":
                records = zstandard.ZstdDecompressor().decompress(compressed, max_output_size=size)
            elif compression == "lz4":
                records = lz4.frame.decompress(compressed)
            elif compression == "":
                records = bytes(compressed)
            else:
                self.report.problems.append(f"chunk at byte {body - 9}: unknown compression {compression!r}; skipped")
                return
        except Exception as exc:
            self.report.problems.append(f"chunk at byte {body - 9}: cannot decompress ({exc!r}); skipped")
            return
        if len(records) != size or (crc != 0 and zlib.crc32(records) != crc):
            self.report.problems.append(f"chunk at byte {body - 9}: size or CRC mismatch (corrupt); skipped")
            return
        stop = self._scan(records, 0, len(records))
        self._flush()
        if stop != len(records):
            self.report.problems.append(f"chunk at byte {body - 9}: its record at byte {stop} is incomplete")

    def _salvage_chunk(self, buf: bytes, body: int) -> int:
        """Read the complete messages of a chunk that the file's end cuts off; returns their count."""
        _, _, _, _, name_length = _CHUNK_HEAD.unpack_from(buf, body)
        pos = body + _CHUNK_HEAD.size
        compression = bytes(buf[pos : pos + name_length]).decode("utf-8")
        compressed = buf[pos + name_length + 8 :]
        if compression == "zstd":
            records = zstandard.ZstdDecompressor().decompressobj().decompress(compressed)
        elif compression == "lz4":
            records = lz4.frame.LZ4FrameDecompressor().decompress(compressed)
        elif compression == "":
            records = bytes(compressed)
        else:
            return 0
        before = self._pending_count()
        self._scan(records, 0, len(records))
        return self._pending_count() - before

    def _pending_count(self) -> int:
        return sum(r.pending for r in self.readers.values())

    def _flush(self) -> None:
        for reader in self.readers.values():
            reader.flush()

    def _channel(self, buf: bytes, body: int) -> None:
        channel_id, schema_id = struct.unpack_from("<HH", buf, body)
        topic, pos = _string(buf, body + 4)
        encoding, _ = _string(buf, pos)
        known = self.channel_topics.setdefault(channel_id, topic)
        if known != topic:
            self.report.problems.append(
                f"channel id {channel_id} is defined twice ({known!r} and {topic!r}); kept {known!r}"
            )
            return
        if channel_id in self.routes or channel_id in self.skipped:
            return
        info = classify_topic(topic)
        if info is None:
            self.skipped[channel_id] = (topic, "not a topic of the recording contract")
            return
        rig = self._require_rig()
        if encoding != "json":
            raise RecordingError(f"topic {topic}: message_encoding {encoding!r}, the contract requires 'json'")
        schema = self.schemas.get(schema_id)
        if schema is None:
            raise RecordingError(f"topic {topic}: schema id {schema_id} is not defined, expected jsonschema {info.title!r}")
        title, schema_encoding = schema
        if schema_encoding != "jsonschema" or title != info.title:
            raise RecordingError(
                f"topic {topic}: schema {title!r} ({schema_encoding!r}), the contract requires {info.title!r} (jsonschema)"
            )
        reader = self.readers.get(topic)
        if reader is None:
            name: str = info.kind
            position = None
            if info.kind not in ("truth", "estimate"):
                sensor = rig.sensor_by_topic().get(topic)
                if sensor is None:
                    what = f"{info.kind} named {info.name!r}" if info.name else f"{info.kind} sensor"
                    self.skipped[channel_id] = (topic, f"rig.json has no {what}")
                    return
                name, position = sensor.name, sensor.position
            decode = (self.topics is None or topic in self.topics) and (self.kinds is None or info.kind in self.kinds)
            reader = _ChannelReader(topic, info, name, position, len(rig.truth_stations), decode, rig.beam.biaxial)
            self.readers[topic] = reader
        self.routes[channel_id] = reader

    def _require_rig(self) -> RigDescription:
        if self.rig is None:
            if self.rig_json is None:
                raise RecordingError(
                    f"{self.path}: rig.json is missing: no {RIG_ATTACHMENT!r} attachment before the first "
                    "channel and no rig= given"
                )
            try:
                self.rig = parse_rig(self.rig_json, source=f"rig.json attachment of {self.path}")
            except RigError as exc:
                raise RecordingError(str(exc)) from None
        return self.rig

    # -- result -------------------------------------------------------------------------------

    def _assemble(self) -> Recording:
        rig = self._require_rig()
        report = self.report
        channels: dict[str, Channel] = {}
        spans: list[tuple[int, int]] = []
        for topic, reader in sorted(self.readers.items()):
            if not reader.decode:
                if reader.raw_min is not None and reader.raw_max is not None:
                    spans.append((reader.raw_min, reader.raw_max))
                continue
            width = sum(1 if s == 0 else (s or 0) for s in reader.sizes)
            channel = channels[topic] = reader.finish(width, self._limits())
            report.topics[topic] = reader.report
            if len(channel):
                spans.append((int(channel.log_time_ns[0]), int(channel.log_time_ns[-1])))
        start = min((s for s, _ in spans), default=0)
        end = max((e for _, e in spans), default=0)
        skipped_counts = Counter(self.unrouted)
        for channel_id, (topic, reason) in self.skipped.items():
            count = skipped_counts.pop(channel_id, 0)
            report.skipped_topics[topic] = report.skipped_topics.get(topic, 0) + count
            report.problems.append(f"{topic}: {reason}; {count} message(s) skipped")
        if skipped_counts:
            report.problems.append(
                f"{sum(skipped_counts.values())} message(s) on undefined channel ids {sorted(skipped_counts)} skipped"
            )
        for topic, channel in channels.items():
            _describe_topic(report, self._limits(), self.readers[topic], channel, start, end)
        # an estimate file holds the estimator's output, not the rig's sensors: none is missing
        estimates_only = any(r.info.kind == "estimate" for r in self.readers.values()) and not any(
            r.info.kind not in ("estimate", "truth") for r in self.readers.values())
        for sensor in rig.sensors:
            if estimates_only:
                break
            if sensor.topic not in self.readers and (self.topics is None or sensor.topic in self.topics):
                report.problems.append(f"rig.json lists {sensor.kind} {sensor.name!r} but the recording has no {sensor.topic}")
        return Recording(self.path, rig, channels, self.metadata, tuple(self.attachments), report, start, end)

    def _limits(self) -> ValueLimits:
        """The recording's own limits (``shm import`` writes its map's in the ``import`` metadata), else the defaults."""
        text = self.metadata.get("import", {}).get("limits")
        if text is None:
            return _LIMITS
        try:
            return ValueLimits.model_validate_json(text)
        except ValueError:
            return _LIMITS


def _describe_topic(report: Any, limits: ValueLimits, reader: _ChannelReader, channel: Channel, start: int, end: int) -> None:
    """What went wrong on one topic, appended to ``report.problems``."""
    r, problems, topic = reader.report, report.problems, channel.topic
    if reader.first_malformed is not None:
        time, reason = reader.first_malformed
        problems.append(f"{topic}: {r.malformed} malformed message(s) skipped (first at log_time {time} ns: {reason})")
    if reader.first_nonfinite is not None:
        problems.append(
            f"{topic}: {r.nonfinite} message(s) with NaN or infinite values skipped "
            f"(first at log_time {reader.first_nonfinite} ns)"
        )
    if reader.first_implausible is not None:
        problems.append(
            f"{topic}: {r.implausible} message(s) with values beyond what a {channel.kind} sensor reads skipped "
            f"(first at log_time {reader.first_implausible} ns; limits: {limits.model_dump()})"
        )
    if r.duplicate:
        problems.append(f"{topic}: {r.duplicate} message(s) with a repeated time stamp skipped")
    if r.backwards:
        problems.append(f"{topic}: {r.backwards} message(s) stamped before the previous sample skipped")
    period = NOMINAL_PERIOD_NS.get(channel.kind)
    if r.gaps and period is not None:  # gaps are counted only for a kind with a nominal period
        problems.append(f"{topic}: {r.gaps} gap(s), {r.missing_samples} sample(s) missing at {1e9 / period:.2f} Hz")
    if r.messages and not r.accepted:
        problems.append(f"{topic}: no valid sample")
    elif period is not None and r.accepted and end - int(channel.log_time_ns[-1]) > SILENT_AFTER_NS:
        r.silent_after_s = (int(channel.log_time_ns[-1]) - start) / 1e9
        problems.append(
            f"{topic}: silent after {r.silent_after_s:.3f} s "
            f"({(end - int(channel.log_time_ns[-1])) / 1e9:.3f} s before the end of the recording)"
        )
