"""Writing recordings (MCAP files of the recording contract).

The message path is written here rather than through ``mcap.writer.Writer``: the library builds
a record object and several small writes per message (about 4 µs each), which made a one-hour
recording slow to write. The file layout is the library's (chunked, message indexes, summary
with schemas, channels, statistics and indexes, summary offsets, CRCs), so any MCAP reader
opens it; the non-message records are written with ``mcap.records``.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final

import lz4.frame
import numpy as np
import orjson
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from contract import SCHEMAS, RigDescription, classify_topic, parse_rig

__all__ = ["RecordingWriter", "encode_payloads_json"]

MAGIC: Final = b"\x89MCAP0\r\n"
LIBRARY: Final = "imms-shm"
RIG_ATTACHMENT: Final = "rig.json"
COMPRESSIONS: Final = ("zstd", "lz4", "none")

# opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_MESSAGE_HEAD_SIZE: Final = _MESSAGE_HEAD.size - 9  # the message body before its data
# the same head as a packed numpy record, for writing many messages at once
_MESSAGE_HEAD_DTYPE: Final = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                                       ("log_time", "<u8"), ("publish_time", "<u8")])
assert _MESSAGE_HEAD_DTYPE.itemsize == _MESSAGE_HEAD.size
_ORJSON_OPTIONS: Final = orjson.OPT_SERIALIZE_NUMPY


class _ChannelState:
    """A registered channel and the message index of the chunk being built."""

    __slots__ = ("channel", "sequence", "times", "offsets", "message_count")

    def __init__(self, channel: Channel) -> None:
        self.channel = channel
        self.sequence = 0  # of the next message
        self.times: list[int] = []
        self.offsets: list[int] = []
        self.message_count = 0


class RecordingWriter:
    """Writes one recording: ``rig.json`` attachment first, then JSON messages in chunks.

    Use as a context manager (``close()`` on exit). Times are integer nanoseconds of any epoch;
    ``log_time`` is the measurement instant, ``publish_time`` (>= ``log_time``) when it was
    written. Payload dicts are encoded with orjson (numpy arrays allowed; note that orjson
    writes NaN and infinities as ``null``, which readers count as malformed).
    """

    def __init__(
        self,
        path: str | Path,
        rig: RigDescription | bytes | str | Mapping[str, Any],
        *,
        metadata: Mapping[str, Mapping[str, str]] | None = None,
        compression: str = "zstd",
        chunk_size: int = 1 << 20,
    ) -> None:
        """Open ``path`` and write the header and the ``rig.json`` attachment.

        ``rig`` is a parsed description, its JSON text (written unchanged after validation) or
        a mapping. ``metadata`` records are written here, after the attachment (a file cut off
        later keeps them). ``compression`` is
        ``"zstd"``, ``"lz4"`` or ``"none"``; ``chunk_size`` is the uncompressed chunk size in
        bytes after which a chunk is written.
        """
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression={compression!r} is not one of {COMPRESSIONS}")
        if chunk_size <= 0:
            raise ValueError(f"chunk_size={chunk_size} must be positive")
        rig_json = _rig_json(rig)
        self._pending_metadata = {name: _checked_metadata(name, data) for name, data in (metadata or {}).items()}
        self._compression = compression
        self._compressor = zstandard.ZstdCompressor() if compression == "zstd" else None
        self._chunk_size = chunk_size
        self._chunk = bytearray()
        self._chunk_message_count = 0
        self._schemas: dict[str, Schema] = {}
        self._channels: dict[str, _ChannelState] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._chunk_count = 0
        self._message_start = 0
        self._message_end = 0
        self._message_count = 0
        self._closed = False
        self._out: IO[bytes] = open(path, "wb")
        try:
            self._out.write(MAGIC)
            self._write_record(Header(profile="", library=LIBRARY))
            offset = self._out.tell()
            length = self._write_record(
                Attachment(create_time=0, log_time=0, name=RIG_ATTACHMENT, media_type="application/json", data=rig_json)
            )
            self._attachment_indexes.append(
                AttachmentIndex(
                    offset=offset,
                    length=length,
                    log_time=0,
                    create_time=0,
                    data_size=len(rig_json),
                    name=RIG_ATTACHMENT,
                    media_type="application/json",
                )
            )
            # the metadata at the start, with the rig: a file cut off mid-write keeps what its
            # analysis needs (an estimate file's end of the rest phase, an import's rejections)
            for name, data in self._pending_metadata.items():
                self.add_metadata(name, data)
        except BaseException:
            self._out.close()
            raise

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def write(
        self, topic: str, log_time_ns: int, payload: Mapping[str, Any] | bytes, publish_time_ns: int | None = None
    ) -> None:
        """Add one message on ``topic`` measured at ``log_time_ns`` (ns).

        ``payload`` is a dict (encoded as JSON) or already encoded JSON bytes (written as is).
        ``publish_time_ns`` defaults to ``log_time_ns``.
        """
        state = self._channels.get(topic)
        if state is None:
            state = self._register(topic)
        data = payload if isinstance(payload, bytes) else orjson.dumps(payload, option=_ORJSON_OPTIONS)
        if publish_time_ns is None:
            publish_time_ns = log_time_ns
        elif publish_time_ns < log_time_ns:
            raise ValueError(f"{topic}: publish_time_ns={publish_time_ns} is before log_time_ns={log_time_ns}")
        chunk = self._chunk
        offset = len(chunk)
        try:
            chunk += _MESSAGE_HEAD.pack(
                Opcode.MESSAGE,
                _MESSAGE_HEAD_SIZE + len(data),
                state.channel.id,
                state.sequence & 0xFFFFFFFF,
                log_time_ns,
                publish_time_ns,
            )
        except struct.error as exc:
            raise ValueError(
                f"{topic}: times must be integers in [0, 2**64) ns, got {log_time_ns=!r}, {publish_time_ns=!r}"
            ) from exc
        state.sequence += 1
        chunk += data
        state.times.append(log_time_ns)
        state.offsets.append(offset)
        self._chunk_message_count += 1
        if len(chunk) >= self._chunk_size:
            self._finish_chunk()

    def write_batch(
        self, topic: str, log_times_ns: Any, payloads: Sequence[bytes], publish_times_ns: Any | None = None
    ) -> None:
        """Add messages of one ``topic``, as ``write(topic, t, p, pub)`` for each in order would
        (the same bytes, chunks cut at the same messages) without a Python step per message.

        ``log_times_ns`` and ``publish_times_ns`` (default: the log times) are integer arrays,
        one time per payload; ``payloads`` are encoded JSON ``bytes``.
        """
        n = len(payloads)
        log = np.asarray(log_times_ns)
        pub = log if publish_times_ns is None else np.asarray(publish_times_ns)
        for name, times in (("log_times_ns", log), ("publish_times_ns", pub)):
            if times.shape != (n,) or (n and times.dtype.kind not in "iu"):
                raise ValueError(f"{topic}: {name} must be {n} integers (one per payload), got shape {times.shape} "
                                 f"of {times.dtype}")
        if n == 0:
            return
        if log.min() < 0 or pub.min() < 0:
            raise ValueError(f"{topic}: times must be integers in [0, 2**64) ns, got a negative one")
        if np.any(pub < log):
            k = int(np.argmax(pub < log))
            raise ValueError(f"{topic}: publish_time_ns={int(pub[k])} is before log_time_ns={int(log[k])}")
        state = self._channels.get(topic)
        if state is None:
            state = self._register(topic)
        lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=n)
        heads = np.empty(n, dtype=_MESSAGE_HEAD_DTYPE)
        heads["opcode"] = Opcode.MESSAGE
        heads["length"] = _MESSAGE_HEAD_SIZE + lengths
        heads["channel"] = state.channel.id
        heads["sequence"] = (state.sequence + np.arange(n, dtype=np.int64)) & 0xFFFFFFFF
        heads["log_time"] = log
        heads["publish_time"] = pub
        state.sequence += n
        ends = np.cumsum(lengths + _MESSAGE_HEAD_DTYPE.itemsize)  # each record's end, from the batch's start
        size = _MESSAGE_HEAD_DTYPE.itemsize
        lo = 0
        while lo < n:
            chunk = self._chunk
            base = len(chunk) - (int(ends[lo - 1]) if lo else 0)  # chunk offset of the batch's start
            # the chunk is finished after the first message that takes it to chunk_size
            hi = min(int(np.searchsorted(ends, self._chunk_size - base, side="left")), n - 1) + 1
            hi = max(hi, lo + 1)
            head_bytes = heads[lo:hi].tobytes()
            parts: list[bytes] = [b""] * (2 * (hi - lo))
            parts[0::2] = [head_bytes[k : k + size] for k in range(0, len(head_bytes), size)]
            parts[1::2] = payloads[lo:hi]
            state.offsets.extend((base + np.concatenate([[int(ends[lo - 1]) if lo else 0], ends[lo : hi - 1]])).tolist())
            state.times.extend(log[lo:hi].tolist())
            chunk += b"".join(parts)
            self._chunk_message_count += hi - lo
            lo = hi
            if len(chunk) >= self._chunk_size:
                self._finish_chunk()

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write a metadata record ``name`` (string keys and values) now."""
        self._check_open()
        record = Metadata(name=name, metadata=_checked_metadata(name, data))
        offset = self._out.tell()
        length = self._write_record(record)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    def flush(self) -> None:
        """End the current chunk and flush the file, so that a reader following it sees the
        messages written so far."""
        self._check_open()
        self._finish_chunk()
        self._out.flush()

    def close(self) -> None:
        """Write the last chunk, the summary and the footer."""
        if self._closed:
            return
        try:
            self._finish_chunk()
            self._write_record(DataEnd(data_section_crc=0))
            self._write_summary()
        finally:
            self._closed = True
            self._out.close()

    # -- internals ----------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise ValueError("the recording writer is closed")

    def _register(self, topic: str) -> _ChannelState:
        self._check_open()
        info = classify_topic(topic)
        if info is None:
            raise ValueError(f"topic {topic!r} is not a topic of the recording contract")
        schema = self._schemas.get(info.title)
        builder = RecordBuilder()
        if schema is None:
            schema = Schema(
                id=len(self._schemas) + 1,
                name=info.title,
                encoding="jsonschema",
                data=json.dumps(SCHEMAS[info.title]).encode(),
            )
            self._schemas[info.title] = schema
            schema.write(builder)
        channel = Channel(
            id=len(self._channels) + 1, topic=topic, message_encoding="json", metadata={}, schema_id=schema.id
        )
        channel.write(builder)
        self._chunk += builder.end()
        state = self._channels[topic] = _ChannelState(channel)
        return state

    def _write_record(self, record: Any) -> int:
        """Write one record at the current position; returns its length in bytes."""
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        self._out.write(data)
        return len(data)

    def _finish_chunk(self) -> None:
        if self._chunk_message_count == 0:
            return
        active = [state for state in self._channels.values() if state.times]
        index = _write_chunk(self._out, bytes(self._chunk), active, self._compression, self._compressor)
        self._chunk_indexes.append(index)
        start, end = index.message_start_time, index.message_end_time
        self._message_start = start if self._message_count == 0 else min(self._message_start, start)
        self._message_end = max(self._message_end, end)
        self._message_count += self._chunk_message_count
        self._chunk_count += 1
        self._chunk.clear()
        self._chunk_message_count = 0

    def _write_summary(self) -> None:
        summary_start = self._out.tell()
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: list[Any]) -> None:
            begin = builder.count
            for record in records:
                record.write(builder)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + begin, group_length=builder.count - begin))

        statistics = Statistics(
            attachment_count=len(self._attachment_indexes),
            channel_count=len(self._channels),
            channel_message_counts={s.channel.id: s.message_count for s in self._channels.values()},
            chunk_count=self._chunk_count,
            message_count=self._message_count,
            message_end_time=self._message_end,
            message_start_time=self._message_start,
            metadata_count=len(self._metadata_indexes),
            schema_count=len(self._schemas),
        )
        group(Opcode.SCHEMA, list(self._schemas.values()))
        group(Opcode.CHANNEL, [s.channel for s in self._channels.values()])
        group(Opcode.STATISTICS, [statistics])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(
            struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start), zlib.crc32(summary)
        )
        self._out.write(summary)
        self._write_record(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc))
        self._out.write(MAGIC)


def _rig_json(rig: RigDescription | bytes | str | Mapping[str, Any]) -> bytes:
    """The ``rig.json`` attachment's bytes: a parsed description's JSON, given JSON text unchanged
    (after validation), or a mapping's JSON."""
    if isinstance(rig, RigDescription):
        return rig.to_json().encode()
    if isinstance(rig, (bytes, str)):
        parse_rig(rig)
        return rig.encode() if isinstance(rig, str) else bytes(rig)
    rig_json = json.dumps(rig, indent=2).encode()
    parse_rig(rig_json)
    return rig_json


def _write_chunk(out: IO[bytes], data: bytes, active: list[_ChannelState], compression: str,
                 compressor: Any) -> ChunkIndex:
    """Write one chunk of ``data`` (the messages of the ``active`` channels) and its message
    indexes at ``out``'s position; the channels' pending times go to their counts. Returns the
    chunk's index record."""
    start = min(min(state.times) for state in active)
    end = max(max(state.times) for state in active)
    if compression == "zstd":
        assert compressor is not None
        compressed, name = compressor.compress(data), "zstd"
    elif compression == "lz4":
        compressed, name = lz4.frame.compress(data), "lz4"
    elif compression == "none":
        compressed, name = data, ""
    else:
        raise ValueError(f"compression={compression!r} is not one of {COMPRESSIONS}")
    chunk_offset = out.tell()
    head = struct.pack("<QQQII", start, end, len(data), zlib.crc32(data), len(name)) + name.encode()
    body_length = len(head) + 8 + len(compressed)
    out.write(struct.pack("<BQ", Opcode.CHUNK, body_length) + head + struct.pack("<Q", len(compressed)))
    out.write(compressed)
    index_start = out.tell()
    index_offsets: dict[int, int] = {}
    for state in active:
        entries = np.empty((len(state.times), 2), dtype="<u8")
        entries[:, 0] = state.times
        entries[:, 1] = state.offsets
        record = entries.tobytes()
        index_offsets[state.channel.id] = out.tell()
        out.write(struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 6 + len(record), state.channel.id, len(record)) + record)
        state.message_count += len(state.times)
        state.times.clear()
        state.offsets.clear()
    return ChunkIndex(
        message_start_time=start, message_end_time=end, chunk_start_offset=chunk_offset, chunk_length=9 + body_length,
        message_index_offsets=index_offsets, message_index_length=out.tell() - index_start, compression=name,
        compressed_size=len(compressed), uncompressed_size=len(data),
    )


def _checked_metadata(name: str, data: Mapping[str, str]) -> dict[str, str]:
    """``data`` as a dict, refusing keys or values that are not strings (MCAP metadata is text)."""
    for key, value in data.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise TypeError(f"metadata {name!r}: key {key!r} -> {value!r} must map a str to a str")
    return dict(data)


def encode_payloads_json(payloads: Sequence[Mapping[str, Any]]) -> list[bytes]:
    """The compact JSON of each payload (flat objects: numbers and lists of numbers), each an
    exact-size ``bytes``.

    ``orjson.dumps`` of one small object returns bytes whose allocation is about 4 kB whatever
    their length (30x a 150-byte payload): a queue of raw messages held that way costs tens of
    MiB. One ``dumps`` of the whole list, cut at the objects' closing braces, gives the same
    bytes at their size."""
    if not payloads:
        return []
    joined = orjson.dumps(payloads, option=_ORJSON_OPTIONS)
    ends = np.flatnonzero(np.frombuffer(joined, dtype=np.uint8) == 0x7D)  # '}'
    if len(ends) != len(payloads):  # a nested object: encode one by one, copied to size
        return [bytes(memoryview(orjson.dumps(p, option=_ORJSON_OPTIONS))) for p in payloads]
    starts = np.empty_like(ends)
    starts[0] = 1
    starts[1:] = ends[:-1] + 2  # after "},"
    return [joined[a : b + 1] for a, b in zip(starts.tolist(), ends.tolist())]
