"""Validation of ingested messages (``POST /api/ingest``) against the recording contract.

A request body is ``{"messages": [{"topic": ..., "log_time_ns": ..., "publish_time_ns": ...
(optional), "payload": {...}}]}`` with payloads as in recordings. A body that is not such a
document is refused as a whole; within it, each message that breaks the contract, lies off the
source's clock or reads beyond what a sensor can is rejected and counted with its reason, and
every valid one is kept. Nothing a message holds makes the request fail (no 500).
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from itertools import chain
from typing import Any, Final

import numpy as np
import orjson

from contract import RigDescription

from ...recording import PAYLOAD_FIELDS, FollowBlock, classify_topic
from ...recording._writer import encode_payloads_json
from ...recording._plausibility import SourceClock, ValueLimits, implausible_row, implausible_values

__all__ = ["IngestError", "IngestResult", "IngestValidator"]

_MAX_NS = 2**63 - 1
_SENSOR_KINDS = ("imu", "tof", "strain", "bearing", "temperature")


class _RecentStamps:
    """The last ``size`` accepted stamps of a topic (a set for the look-up, a deque for the order)."""

    def __init__(self, size: int = 100_000) -> None:
        self.size = size
        self.order: deque[int] = deque()
        self.members: set[int] = set()

    def add(self, stamps: Any) -> None:
        for stamp in np.asarray(stamps, dtype=np.int64).tolist():
            if stamp not in self.members:
                self.members.add(stamp)
                self.order.append(stamp)
        while len(self.order) > self.size:
            self.members.discard(self.order.popleft())

    def __contains__(self, stamp: int) -> bool:
        return stamp in self.members


class IngestError(ValueError):
    """The request body as a whole is unusable (the message says why)."""


@dataclass
class IngestResult:
    blocks: list[FollowBlock]
    raw: list[tuple[str, int, bytes, int]]
    accepted: int = 0
    rejected: Counter = field(default_factory=Counter)
    errors: list[dict[str, Any]] = field(default_factory=list)
    clock: SourceClock | None = None  # the source's clock after this batch (adopted by ``commit``)
    last: dict[str, int] | None = None  # the topics' last times after this batch
    refused_by_topic: Counter = field(default_factory=Counter)  # rejections of the rig's topics

    def as_dict(self) -> dict[str, Any]:
        return {"accepted": self.accepted, "rejected": sum(self.rejected.values()),
                "rejected_by_reason": dict(self.rejected), "errors": self.errors}


def parse_body(body: bytes) -> Any:
    """JSON (orjson, with the stdlib as fallback for NaN/Infinity tokens, which are then
    rejected per message)."""
    try:
        return orjson.loads(body)
    except orjson.JSONDecodeError as exc:
        try:
            return json.loads(body)
        except (ValueError, RecursionError, UnicodeDecodeError):
            raise IngestError(f"body is not valid JSON: {exc}") from None


class IngestValidator:
    """Checks messages of the rig's topics. Keeps the last accepted time per topic, so a sample
    stamped at or before the previous one is rejected (``backwards``/``duplicate``), and the
    source's clock (``SourceClock``): stamps far from it are rejected (``implausible_time``,
    ``ahead_of_source``), as are values no sensor can read (``implausible_value``).

    ``validate`` changes nothing: it returns the result with the state after it, and ``commit``
    adopts that state once the batch is handed on. A request that is refused (the pipeline is
    full) or fails therefore never makes its retry look like a duplicate."""

    def __init__(self, rig: RigDescription, *, max_messages: int, clock: SourceClock | None = None,
                 limits: ValueLimits | None = None) -> None:
        self.rig = rig
        self.sensors = rig.sensor_by_topic()
        self.max_messages = max_messages
        self.last: dict[str, int] = {}
        self.clock = clock or SourceClock(window_s=3600.0, max_ahead_s=1.0, live=True)
        self.limits = limits or ValueLimits()
        self.max_errors = 20
        self._info: dict[str, Any] = {}
        # the stamps accepted lately per topic: a re-sent batch is ``duplicate``, not ``backwards``
        self.recent: dict[str, _RecentStamps] = {}

    def validate(self, document: Any, *, wall_ns: int | None = None) -> IngestResult:
        if not isinstance(document, dict) or "messages" not in document:
            raise IngestError('body must be a JSON object {"messages": [...]}')
        extra = set(document) - {"messages"}
        if extra:
            raise IngestError(f"unknown key(s) {sorted(extra)} in the body; only 'messages' is allowed")
        messages = document["messages"]
        if not isinstance(messages, list):
            raise IngestError("'messages' must be a list")
        if len(messages) > self.max_messages:
            raise IngestError(f"{len(messages)} messages in one request; at most {self.max_messages}")
        wall = time.time_ns() if wall_ns is None else wall_ns
        mono = time.monotonic()
        fast = self._validate_columns(messages, wall, mono)
        if fast is not None:
            return fast
        clock = self.clock.copy()
        last = dict(self.last)
        whole = clock.source_jump(_first_stamps(messages, self.sensors), mono)
        judge = clock.judge_stamps(wall_ns=wall, mono=mono, whole_source=whole)
        result = IngestResult([], [], clock=clock, last=last)
        # the validated payloads, encoded into result.raw's bytes once the batch is read
        validated: list[tuple[str, int, dict, int]] = []
        rows: dict[str, tuple[list[int], list[int], list[list[float]]]] = {}
        off_clock: dict[tuple[str, str], list[int]] = {}
        for index, message in enumerate(messages):
            try:
                topic, log_ns, pub_ns, row, payload = self._message(message)
                previous = last.get(topic)
                if previous is not None and log_ns <= previous and (
                        log_ns == previous or (topic in self.recent and log_ns in self.recent[topic])):
                    # accepted before (a re-sent batch), however far behind the clock it now lies
                    raise _Reject("duplicate", f"{topic}: log_time_ns {log_ns} was accepted before")
                code = judge.judge(topic, log_ns)
                if code:
                    reason = "implausible_time" if code == 1 else "ahead_of_source"
                    off_clock.setdefault((topic, reason), []).append(log_ns)
                    raise _Reject(reason, f"{topic}: log_time_ns {log_ns} is {clock.offset_s(topic, log_ns, mono):+.3g} s "
                                          f"off the source's clock ({_REASONS[reason]})")
                if previous is not None and log_ns <= previous:
                    raise _Reject("backwards", f"{topic}: log_time_ns {log_ns} is not after the previous sample's {previous}")
            except _Reject as exc:
                result.rejected[exc.reason] += 1
                if isinstance(message, dict) and message.get("topic") in self.sensors:
                    result.refused_by_topic[message["topic"]] += 1
                if len(result.errors) < self.max_errors:
                    result.errors.append({"index": index, "reason": exc.reason, "detail": str(exc)})
                continue
            except Exception as exc:  # noqa: BLE001 - whatever a message holds, it is its own rejection, never a 500
                result.rejected["malformed"] += 1
                if len(result.errors) < self.max_errors:
                    result.errors.append({"index": index, "reason": "malformed", "detail": f"{type(exc).__name__}: {exc}"[:300]})
                continue
            last[topic] = log_ns
            judge.take(topic, log_ns)
            t, p, v = rows.setdefault(topic, ([], [], []))
            t.append(log_ns)
            p.append(pub_ns)
            v.append(row)
            validated.append((topic, log_ns, payload, pub_ns))
            result.accepted += 1
        for (topic, reason), stamps in off_clock.items():
            clock.record(topic, reason, len(stamps), clock.offset_s(topic, stamps[0], mono))
        if whole:
            firsts = [t[0] for t, _, _ in rows.values()]
            if firsts:
                clock.record(None, "source_jump", result.accepted, clock.offset_s(None, min(firsts), mono))
        # exact-size bytes (one orjson dump per block: orjson's own are ~4 kB each), written from
        # the validated numbers, never the client's bytes
        encoded = encode_payloads_json([m[2] for m in validated])
        result.raw = [(topic, log_ns, data, pub_ns) for (topic, log_ns, _, pub_ns), data in zip(validated, encoded)]
        for topic, (t, p, v) in rows.items():
            sensor = self.sensors[topic]
            info = classify_topic(topic)
            assert info is not None, "an accepted topic is a sensor's, which classifies"
            result.blocks.append(FollowBlock(topic, info.kind, sensor.name, np.array(t, dtype=np.int64),
                                             np.array(p, dtype=np.int64), np.array(v, dtype=np.float64)))
        return result

    def commit(self, result: IngestResult) -> None:
        """The batch of ``result`` was handed on: its times are the topics' and the clock's."""
        if result.last is not None:
            self.last = result.last
        for block in result.blocks:
            self.recent.setdefault(block.topic, _RecentStamps()).add(block.log_time_ns)
        if result.clock is not None:
            self.clock = result.clock

    def _message(self, message: Any) -> tuple[str, int, int, list[float], dict]:
        if not isinstance(message, dict):
            raise _Reject("malformed", f"a message must be an object, got {type(message).__name__}")
        unknown = set(message) - {"topic", "log_time_ns", "publish_time_ns", "payload"}
        if unknown:
            raise _Reject("malformed", f"unknown key(s) {sorted(unknown)[:5]}")
        topic = message.get("topic")
        if not isinstance(topic, str):
            raise _Reject("malformed", "'topic' must be a string")
        info = self._info.get(topic)
        if info is None:
            info = classify_topic(topic)
            if info is not None and topic in self.sensors:
                self._info[topic] = info
        if info is None or info.kind not in _SENSOR_KINDS:
            raise _Reject("unknown_topic", f"topic {topic[:80]!r} is not a sensor topic of the recording contract")
        if topic not in self.sensors:
            raise _Reject("unknown_topic", f"topic {topic[:80]!r}: rig.json has no such sensor")
        log_ns = message.get("log_time_ns")
        if isinstance(log_ns, bool) or not isinstance(log_ns, int) or not 0 <= log_ns <= _MAX_NS:
            raise _Reject("malformed", f"{topic}: 'log_time_ns' must be an integer in [0, 2**63)")
        pub_ns = message.get("publish_time_ns", log_ns)
        if isinstance(pub_ns, bool) or not isinstance(pub_ns, int) or not log_ns <= pub_ns <= _MAX_NS:
            raise _Reject("malformed", f"{topic}: 'publish_time_ns' must be an integer >= log_time_ns")
        payload = message.get("payload")
        if not isinstance(payload, dict):
            raise _Reject("wrong_schema", f"{topic}: 'payload' must be an object ({info.title})")
        row: list[float] = []
        fields = PAYLOAD_FIELDS[info.title]
        extra = set(payload) - {f.name for f in fields}
        if extra:
            raise _Reject("wrong_schema", f"{topic}: payload key(s) {sorted(map(str, extra))[:5]} are not in {info.title}")
        canonical: dict[str, Any] = {}
        for spec in fields:
            if spec.name not in payload:
                raise _Reject("wrong_schema", f"{topic}: payload lacks {spec.name!r} ({info.title})")
            value = payload[spec.name]
            if spec.size == 0:
                x = _number(topic, spec.name, value)
                row.append(x)
                canonical[spec.name] = x
            else:
                if not isinstance(value, list) or len(value) != spec.size:
                    raise _Reject("wrong_schema", f"{topic}: {spec.name!r} must be a list of {spec.size} numbers")
                xs = [_number(topic, f"{spec.name}[{i}]", x) for i, x in enumerate(value)]
                row.extend(xs)
                canonical[spec.name] = xs
        if not all(math.isfinite(x) for x in row):
            raise _Reject("nonfinite", f"{topic}: NaN, infinite or out-of-range number at log_time_ns {log_ns}")
        if implausible_row(info.kind, row, self.limits):
            raise _Reject("implausible_value", f"{topic}: {row} at log_time_ns {log_ns} is beyond what the sensor can "
                                               f"read (limits: source.limits)")
        # The payload recorded is written from the validated numbers, never the client's bytes.
        return topic, log_ns, pub_ns, row, canonical


    def _validate_columns(self, messages: list, wall_ns: int, mono: float) -> IngestResult | None:
        """The whole request at once, column by column, when every message is clean: the rig's
        sensor topics, integer stamps in range and on the source's clock (no source-wide jump),
        payloads with exactly their schema's keys and finite, plausible numbers, each topic's
        stamps increasing after its last accepted one. Returns
        None as soon as anything is not (the message-by-message path then counts and explains
        each rejection); for a clean request both paths give the same result."""
        if not messages:
            return None
        try:
            if set(map(type, messages)) != {dict}:
                return None
            sizes = set(map(len, messages))
            # 3 keys that are topic, log_time_ns and payload, or 4 with publish_time_ns: nothing else
            if sizes not in ({3}, {4}) and not all(m.keys() <= _MESSAGE_KEYS for m in messages):
                return None
            topics = [m["topic"] for m in messages]
            stamps = [m["log_time_ns"] for m in messages]
            payloads = [m["payload"] for m in messages]
            if sizes == {4}:
                published = [m["publish_time_ns"] for m in messages]
            else:
                published = [m.get("publish_time_ns", t) for m, t in zip(messages, stamps)]
        except (KeyError, TypeError):
            return None
        if set(map(type, stamps)) != {int} or set(map(type, published)) != {int} or set(map(type, payloads)) != {dict}:
            return None
        try:
            log_ns = np.array(stamps, dtype=np.int64)
            pub_ns = np.array(published, dtype=np.int64)
        except OverflowError:
            return None
        if log_ns.min() < 0 or (pub_ns < log_ns).any():
            return None
        if int(log_ns.max()) > _MAX_NS or int(pub_ns.max()) > _MAX_NS:
            return None
        clock = self.clock.copy()
        if clock.source_jump(_first_stamps(messages, self.sensors), mono):
            return None
        judge = clock.judge_stamps(wall_ns=wall_ns, mono=mono, whole_source=False)
        for topic, stamp in zip(topics, stamps):
            if not isinstance(topic, str) or topic not in self.sensors or judge.judge(topic, stamp):
                return None
            judge.take(topic, stamp)
        groups: dict[str, list[int]] = {}
        for index, topic in enumerate(topics):
            groups.setdefault(topic, []).append(index)
        blocks: list[FollowBlock] = []
        last = dict(self.last)
        for topic, members in groups.items():
            sensor = self.sensors.get(topic) if isinstance(topic, str) else None
            if sensor is None:
                return None
            info = classify_topic(topic)
            if info is None or info.kind not in _SENSOR_KINDS:
                return None
            values = _payload_columns(PAYLOAD_FIELDS[info.title], [payloads[i] for i in members])
            if values is None or implausible_values(info.kind, values, self.limits).any():
                return None
            rows = np.asarray(members)
            t = log_ns[rows]
            before = last.get(topic)
            if (before is not None and t[0] <= before) or (len(t) > 1 and (t[1:] <= t[:-1]).any()):
                return None
            last[topic] = int(t[-1])
            blocks.append(FollowBlock(topic, info.kind, sensor.name, t, pub_ns[rows], values))
        try:
            encoded = encode_payloads_json(payloads)
        except orjson.JSONEncodeError:  # an integer beyond 64 bits
            return None
        raw = list(zip(topics, stamps, encoded, published))
        return IngestResult(blocks, raw, accepted=len(messages), clock=clock, last=last)


_REASONS = {"implausible_time": "outside the plausible window around it (source.time_window_s), or beyond the wall "
                                "clock plus source.future_tolerance_s",
            "ahead_of_source": "ahead of every other sensor of the source by more than source.max_ahead_s"}


def _first_stamps(messages: list, sensors: dict) -> dict[str, int]:
    """The first stamp of each topic in a request (for the whole-source jump test)."""
    firsts: dict[str, int] = {}
    for m in messages:
        if isinstance(m, dict):
            topic, t = m.get("topic"), m.get("log_time_ns")
            if isinstance(topic, str) and topic in sensors and topic not in firsts and isinstance(t, int) \
                    and not isinstance(t, bool) and 0 <= t <= _MAX_NS:
                firsts[topic] = t
    return firsts


_MESSAGE_KEYS: Final = frozenset({"topic", "log_time_ns", "publish_time_ns", "payload"})


def _payload_columns(fields, payloads: list[dict]) -> np.ndarray | None:
    """Rows (n, width) of payloads that each hold exactly ``fields`` (scalars and lists of
    their size, numbers only, finite), or None if any does not."""
    if set(map(len, payloads)) != {len(fields)}:
        return None
    columns = []
    try:
        for spec in fields:
            column = [p[spec.name] for p in payloads]
            if spec.size == 0:
                kinds = set(map(type, column))
            else:
                if set(map(type, column)) != {list} or set(map(len, column)) != {spec.size}:
                    return None
                kinds = set(map(type, chain.from_iterable(column)))
            if not kinds <= {float, int}:  # bool, None, str, nested lists: the reference path
                return None
            columns.append(np.array(column, dtype=np.float64).reshape(len(payloads), -1))
    except (KeyError, OverflowError, ValueError, TypeError):
        return None
    values = np.concatenate(columns, axis=1) if len(columns) > 1 else columns[0]
    if not np.isfinite(values).all():
        return None
    return values


def _number(topic: str, name: str, value: Any) -> float:
    if value is None:
        raise _Reject("nonfinite", f"{topic}: {name!r} is null (NaN?)")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _Reject("wrong_schema", f"{topic}: {name!r} must be a number")
    try:
        return float(value)
    except OverflowError:
        return math.inf


class _Reject(ValueError):
    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
