"""Measured channels of DAQ files into the recording contract (``shm import``).

A channel map (TOML, :class:`ChannelMap`) says, per file column, which topic and payload field of
the contract it fills (``/imu/s1`` ``accel`` index 1, ``/strain/g1`` ``strain``, ...), the scale and
offset from the file's units to SI (``SI = scale · value + offset``) and its clock: a time column
of a file or a sample rate, each with an absolute start. The files are read by
:func:`shm_service.formats.tables.read_table` (CSV/TSV/text, LabVIEW exports, ``.npy``/``.npz``, MATLAB v5
and v7.3, HDF5); the recording is written by :class:`shm_service.recording.RecordingWriter` with the
rig description, so it follows the contract exactly.

What a table lacks and how it is written:
- an IMU message has six values (accel xyz, gyro xyz): the fields no column fills are written as
  0.0 and the recording's ``rig.json`` lists the sensor's ``axes`` (an extension key, e.g.
  ``["accel_y"]`` for a single-axis accelerometer); a rig that already lists ``axes`` must get
  exactly those from the map;
- a sample with a NaN or infinite value in any of its topic's columns is not written (the contract's
  readers would reject the message): it is counted per topic as a rejection and reported, and
  every valid sample around it is kept;
- ``publish_time`` is the ``log_time`` (a file has no delivery times).
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Literal

import numpy as np
import orjson
from pydantic import AwareDatetime, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from contract import RigDescription, load_rig

from ..recording import PAYLOAD_FIELDS, RecordingWriter, classify_topic
from .rejections import REASONS, Rejections
from ..recording._plausibility import ValueLimits
from .tables import Table, TableError, read_table

__all__ = [
    "ChannelMap",
    "ClockImport",
    "ClockMap",
    "ColumnMap",
    "ImportReport",
    "MapError",
    "TopicImport",
    "import_recording",
    "load_channel_map",
    "parse_channel_map",
]

#: Kinds of topic a DAQ file may fill (truth and estimates are written by simulators and estimators).
_IMPORTED_KINDS = ("imu", "tof", "strain", "bearing", "temperature")
_AXES = ("x", "y", "z")
_EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
_MAX_NS = 2**63 - 1


class MapError(ValueError):
    """A channel map that is invalid or does not fit the rig or the files (names the key)."""


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ClockMap(_Closed):
    """A time base: ``column`` (a time column of ``file``, in ``unit``) or ``rate_hz`` (the first
    sample at ``start``, then one every 1/rate_hz s).

    ``start`` (a TOML date-time with a UTC offset) or ``start_ns`` (ns since the UNIX epoch) is the
    absolute time of the column's zero, or of the first sample with a rate; default the epoch itself
    (the contract allows any epoch). ``file`` picks one of several DATA files (its name or path);
    it may be left out when there is one.
    """

    file: str | None = Field(None, description="the DATA file this clock times (its name or path as given); may be left out with one file")
    column: str | None = Field(None, description="the name of the file's time column (or give rate_hz)")
    unit: Literal["s", "ms", "us", "ns"] = Field("s", description="the time column's unit")
    rate_hz: float | None = Field(None, gt=0.0, allow_inf_nan=False, description="a sample rate, Hz: row k at start + k/rate_hz (or give column)")
    start: AwareDatetime | None = Field(None, description="absolute time of the column's zero or of the first row, a TOML date-time "
                                        "with a UTC offset (default: the epoch)")
    start_ns: int | None = Field(None, ge=0, le=_MAX_NS, description="the same as ns since the UNIX epoch (not with start)")

    @model_validator(mode="after")
    def _one_time_base(self) -> ClockMap:
        if (self.column is None) == (self.rate_hz is None):
            raise ValueError("give either column (the name of a time column) or rate_hz (a sample rate in Hz), exactly one")
        if self.column is None and "unit" in self.model_fields_set:
            raise ValueError(f"unit={self.unit!r} is the unit of a time column; this clock has rate_hz, no column")
        if self.start is not None and self.start_ns is not None:
            raise ValueError("give start (a date-time) or start_ns (ns since the epoch), not both")
        return self

    def start_time_ns(self) -> int:
        if self.start_ns is not None:
            return self.start_ns
        if self.start is None:
            return 0
        delta = self.start - _EPOCH
        ns = (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
        if ns < 0:
            raise MapError(f"start={self.start.isoformat()} is before 1970-01-01: the contract's times are ns >= 0")
        return ns


class ColumnMap(_Closed):
    """One file column into one payload value: ``topic``, ``field`` and (for a vector field such as
    ``accel``) ``index`` 0, 1 or 2; ``SI = scale · value + offset``; ``clock`` (required when the map
    has several); ``name``, the column's name in the file, defaults to the map's key."""

    topic: str = Field(description="the contract topic it fills, of a sensor of rig.json: /imu/NAME, /tof/NAME, /strain/NAME, "
                       "/bearing/displacement, /env/temperature")
    field: str = Field(description="the payload field: accel or gyro (imu), distance (tof, bearing: displacement), strain, temperature")
    index: int | None = Field(None, ge=0, description="the axis of a vector field, 0/1/2 = sensor x/y/z (required for accel and gyro)")
    scale: float = Field(1.0, allow_inf_nan=False, description="SI = scale · value + offset: the factor from the file's unit to SI (not 0)")
    offset: float = Field(0.0, allow_inf_nan=False, description="… and the offset, in SI")
    clock: str | None = Field(None, description="the clock (a key of [clocks]) that times this column; required when there are several")
    name: str | None = Field(None, min_length=1, description="the column's name in the file (default: this entry's key)")

    @field_validator("scale")
    @classmethod
    def _nonzero(cls, scale: float) -> float:
        if scale == 0.0:
            raise ValueError("scale=0 would erase the column; give the factor from the file's unit to SI")
        return scale


class ChannelMap(_Closed):
    """``[clocks.NAME]`` time bases, ``[columns."COLUMN"]`` entries (see the module docstring) and
    ``[limits]``, the physical limits per sensor kind in SI (``shm serve``'s ``source.limits``:
    ``accel_m_s2``, ``gyro_rad_s``, ``distance_min_m``/``distance_max_m``, ``strain``,
    ``bearing_m``, ``temperature_min_c``/``temperature_max_c``); a value beyond them is rejected
    as ``implausible``."""

    clocks: dict[str, ClockMap] = Field(min_length=1)
    columns: dict[str, ColumnMap] = Field(min_length=1)
    limits: ValueLimits = ValueLimits()

    @model_validator(mode="after")
    def _clocks_known(self) -> ChannelMap:
        for key, column in self.columns.items():
            if column.clock is None and len(self.clocks) > 1:
                raise ValueError(f"columns.{_quote(key)}: give clock = one of {sorted(self.clocks)} (the map has several)")
            if column.clock is not None and column.clock not in self.clocks:
                raise ValueError(f"columns.{_quote(key)}: clock={column.clock!r} is not one of the map's clocks {sorted(self.clocks)}")
        return self

    def clock_of(self, key: str) -> str:
        return self.columns[key].clock or next(iter(self.clocks))


def _quote(key: object) -> str:
    text = str(key)
    return text if text.replace("_", "").replace("-", "").isalnum() else json.dumps(text)


def parse_channel_map(data: dict[str, Any], *, source: str = "channels.toml") -> ChannelMap:
    """Validate a parsed channel map; ``MapError`` names the key of every problem."""
    try:
        return ChannelMap.model_validate(data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            where = ".".join(_quote(p) for p in err["loc"])
            message = err["msg"].removeprefix("Value error, ")
            problems.append(f"{where}: {message}" if where else message)
        raise MapError(f"{source}: " + "; ".join(problems)) from None


def load_channel_map(path: str | Path) -> tuple[ChannelMap, str]:
    """Read and validate the TOML map at ``path``; returns the map and its text."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MapError(f"cannot read the channel map {str(path)!r}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MapError(f"{path}: not valid TOML: {exc}") from None
    return parse_channel_map(data, source=str(path)), text


# -- the plan: what goes where, checked against the rig before any file is read ---------------------
@dataclass(frozen=True)
class _Slot:
    key: str  # the map's key of the column
    column: str  # its name in the file
    offset: int  # position in the topic's row of values
    axis: str  # "accel_y", "strain", ...
    scale: float
    bias: float


@dataclass
class _TopicPlan:
    topic: str
    kind: str
    title: str
    clock: str
    layout: list[tuple[str, int]]  # payload fields and sizes (0: a number)
    width: int
    slots: list[_Slot] = field(default_factory=list)


def _topic_plans(channel_map: ChannelMap, rig: RigDescription, source: str) -> dict[str, _TopicPlan]:
    declared = rig.sensor_by_topic()
    plans: dict[str, _TopicPlan] = {}
    taken: dict[tuple[str, int], str] = {}
    for key, column in channel_map.columns.items():
        where = f"{source}: columns.{_quote(key)}"
        info = classify_topic(column.topic)
        if info is None or info.kind not in _IMPORTED_KINDS:
            raise MapError(f"{where}: topic {column.topic!r} is not a sensor topic of the recording contract "
                           "(/imu/<name>, /tof/<name>, /strain/<name>, /bearing/displacement, /env/temperature)")
        if column.topic not in declared:
            raise MapError(f"{where}: topic {column.topic!r} is not declared by the rig (its sensors give "
                           f"{sorted(declared)}): add the sensor to rig.json or map the column to one of those")
        layout = [(spec.name, int(spec.size)) for spec in PAYLOAD_FIELDS[info.title]]
        offsets, position = {}, 0
        for name, size in layout:
            offsets[name] = position
            position += max(size, 1)
        sizes = dict(layout)
        if column.field not in sizes:
            raise MapError(f"{where}: field {column.field!r} is not a field of {column.topic} ({info.title}: {sorted(sizes)})")
        size = sizes[column.field]
        if size == 0:
            if column.index is not None:
                raise MapError(f"{where}: field {column.field!r} of {column.topic} is a number: it takes no index (index={column.index})")
            offset, axis = offsets[column.field], column.field
        else:
            if column.index is None or column.index >= size:
                raise MapError(f"{where}: field {column.field!r} of {column.topic} is a vector of {size}: "
                               f"give index = 0..{size - 1} (index={column.index})")
            offset, axis = offsets[column.field] + column.index, f"{column.field}_{_AXES[column.index]}"
        clock = channel_map.clock_of(key)
        plan = plans.setdefault(column.topic, _TopicPlan(column.topic, info.kind, info.title, clock, layout, position))
        if plan.clock != clock:
            other = plan.slots[0].key
            raise MapError(f"{where}: {column.topic} takes column {other!r} on clock {plan.clock!r} and this one on "
                           f"clock {clock!r}: one message holds values of one instant, so a topic's columns share a clock")
        if (column.topic, offset) in taken:
            raise MapError(f"{where}: {column.topic} {axis} is already filled by column {taken[column.topic, offset]!r}")
        taken[column.topic, offset] = key
        plan.slots.append(_Slot(key, column.name or key, offset, axis, column.scale, column.offset))
    for topic, plan in plans.items():
        sensor = declared[topic]
        axes = (sensor.model_extra or {}).get("axes")
        if sensor.kind != "imu" or axes is None:
            continue
        known = [f"{f}_{a}" for f in ("accel", "gyro") for a in _AXES]
        if not isinstance(axes, list) or any(a not in known for a in axes):
            raise MapError(f"rig.json: imu {sensor.name!r}: axes={axes!r} must list some of {known}")
        mapped = {slot.axis for slot in plan.slots}
        if mapped != set(axes):
            extra = sorted(mapped - set(axes))
            missing = sorted(set(axes) - mapped)
            raise MapError(f"{source}: {topic}: rig.json lists its axes as {axes}, the map fills {sorted(mapped)}"
                           + (f" ({extra} not in rig.json)" if extra else "") + (f" (no column maps {missing})" if missing else ""))
    return plans


def _resolve_files(channel_map: ChannelMap, data: Sequence[Path], source: str) -> dict[str, Path]:
    """The file each clock reads."""
    files: dict[str, Path] = {}
    for name, clock in channel_map.clocks.items():
        if clock.file is None:
            if len(data) != 1:
                raise MapError(f"{source}: clocks.{_quote(name)}: give file = one of {[p.name for p in data]} (several DATA files)")
            files[name] = data[0]
            continue
        matches = [p for p in data if str(p) == clock.file or p.name == clock.file]
        if len(matches) != 1:
            raise MapError(f"{source}: clocks.{_quote(name)}: file={clock.file!r} is "
                           + ("none" if not matches else "more than one") + f" of the DATA files {[str(p) for p in data]}")
        files[name] = matches[0]
    unused = [str(p) for p in data if p not in files.values()]
    if unused:
        raise MapError(f"{source}: no clock reads {unused}: give the clock's file key, or leave the file out")
    return files


# -- the report ----------------------------------------------------------------------------------
@dataclass
class TopicImport:
    """One topic written: ``messages`` written, ``rejected`` samples not written (the first at
    sample ``first_rejected_row`` of ``first_rejected_column``; one bad column costs the topic
    that sample), ``reasons`` their count by reason, ``by_column`` the rejected values per column
    and reason with the first positions (``shm_service.formats.rejections``), the columns it took, the
    axes written as 0.0 (IMU fields no column fills)."""

    clock: str
    columns: list[str]
    messages: int = 0
    rejected: int = 0
    first_rejected_row: int | None = None
    first_rejected_column: str | None = None
    zero_filled: list[str] = field(default_factory=list)
    reasons: dict[str, int] = field(default_factory=dict)
    by_column: dict[str, Any] = field(default_factory=dict)  # rejected values per column, by reason


@dataclass
class ClockImport:
    file: str
    format: str
    samples: int
    rate_hz: float
    start_ns: int
    first_log_time_ns: int
    last_log_time_ns: int


@dataclass
class ImportReport:
    """What ``import_recording`` wrote: per topic and per clock, the file columns left out, the
    rig's sensors no column fills."""

    out: str
    topics: dict[str, TopicImport]
    clocks: dict[str, ClockImport]
    unused_columns: dict[str, list[str]]
    sensors_without_data: list[str]

    @property
    def messages(self) -> int:
        return sum(t.messages for t in self.topics.values())

    @property
    def rejected(self) -> int:
        return sum(t.rejected for t in self.topics.values())

    def rejected_by_reason(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for t in self.topics.values():
            for reason, n in t.reasons.items():
                out[reason] = out.get(reason, 0) + n
        return out

    def as_dict(self) -> dict[str, Any]:
        return {"out": self.out, "messages": self.messages, "rejected": self.rejected,
                "rejected_by_reason": self.rejected_by_reason(),
                "topics": {k: asdict(v) for k, v in self.topics.items()},
                "clocks": {k: asdict(v) for k, v in self.clocks.items()},
                "unused_columns": self.unused_columns, "sensors_without_data": self.sensors_without_data}

    def format(self) -> str:
        reasons = ", ".join(f"{n} {r}" for r, n in self.rejected_by_reason().items())
        lines = [f"wrote {self.out}: {self.messages} messages, {self.rejected} samples rejected" + (f" ({reasons})" if reasons else "")]
        for name, c in self.clocks.items():
            lines.append(f"clock {name}: {c.file} ({c.format}), {c.samples} samples at {c.rate_hz:.6g} Hz, "
                         f"log_time {c.first_log_time_ns}..{c.last_log_time_ns} ns")
        for topic, t in self.topics.items():
            text = f"  {topic}: {t.messages} messages from {', '.join(t.columns)}"
            if t.rejected:
                text += f"; {t.rejected} rejected (first: row {t.first_rejected_row} of {t.first_rejected_column!r})"
            if t.zero_filled:
                text += f"; {', '.join(t.zero_filled)} written as 0.0 (not measured)"
            lines.append(text)
            for column, entry in t.by_column.items():
                why = ", ".join(f"{n} {r}" + (f" ({entry['limits'][r]})" if r in entry.get("limits", {}) else "")
                                for r, n in entry["reasons"].items())
                first = ", ".join((f"line {p['line']}" if "line" in p else f"sample {p['sample']}") + f" ({p['reason']})"
                                  for p in entry["first"])
                lines.append(f"    {column}: {entry['total']} rejected ({why}); first: {first}")
        for file, columns in self.unused_columns.items():
            lines.append(f"not imported from {file}: {', '.join(columns)}")
        if self.sensors_without_data:
            lines.append(f"rig sensors without a column (the recording has no such topic): {', '.join(self.sensors_without_data)}")
        return "\n".join(lines)


# -- the import ----------------------------------------------------------------------------------
def _log_times(clock: ClockMap, table: Table, where: str) -> np.ndarray:
    """The samples' log_time (ns): the start plus the time column, or plus k / rate."""
    n = table.data.shape[0]
    start = clock.start_time_ns()
    if clock.column is not None:
        t = table.time
        assert t is not None
        # whole ns of the first time, then the steps from it: full ns resolution over long files
        # whatever the column's epoch; rows without a valid time (rejected) get 0, never written
        valid = np.isfinite(t)
        t0 = float(t[valid][0])
        first = start + int(round(t0 * 1e9))
        relative = np.where(valid, np.round((np.where(valid, t, t0) - t0) * 1e9), 0.0)
        if first < 0 or first + relative.max() > _MAX_NS:
            raise MapError(f"{where}: the time column {clock.column!r} gives log times outside [0, 2**63) ns "
                           f"(start {start} ns plus the column's first value {t0!r} s = {first} ns): the column's values "
                           "are added to start; set start or start_ns so that start plus the first value is at or after 1970")
        return np.where(valid, first + relative.astype(np.int64), 0)
    assert clock.rate_hz is not None, "a clock without a column has a rate (ClockMap)"
    step = 1e9 / clock.rate_hz
    if start + step * (n - 1) > _MAX_NS:
        raise MapError(f"{where}: the clock's log times pass 2**63 ns")
    return start + np.round(np.arange(n) * step).astype(np.int64)


def _limit_of(kind: str, axis: str, limits: ValueLimits) -> tuple[float, float, str]:
    """(low, high, text) of what a sensor of ``kind`` reads on ``axis`` (SI), from ``limits``."""
    if axis.startswith("accel"):
        a = limits.accel_m_s2
        return -a, a, f"|{axis}| <= {a:g} m/s² (limits.accel_m_s2)"
    if axis.startswith("gyro"):
        g = limits.gyro_rad_s
        return -g, g, f"|{axis}| <= {g:g} rad/s (limits.gyro_rad_s)"
    if kind == "tof":
        return limits.distance_min_m, limits.distance_max_m, (f"{limits.distance_min_m:g} <= distance <= {limits.distance_max_m:g} m "
                                                              "(limits.distance_min_m, distance_max_m)")
    if kind == "bearing":
        return -limits.bearing_m, limits.bearing_m, f"|displacement| <= {limits.bearing_m:g} m (limits.bearing_m)"
    if kind == "strain":
        return -limits.strain, limits.strain, f"|strain| <= {limits.strain:g} (limits.strain)"
    if kind == "temperature":
        return limits.temperature_min_c, limits.temperature_max_c, (
            f"{limits.temperature_min_c:g} <= celsius <= {limits.temperature_max_c:g} °C (limits.temperature_min_c, temperature_max_c)")
    raise MapError(f"{kind=} {axis=}: no limit known for this sensor kind")


def _payloads(plan: _TopicPlan, values: np.ndarray) -> list[bytes]:
    dumps = orjson.dumps
    rows = values.tolist()
    if len(plan.layout) == 1 and plan.layout[0][1] == 0:
        (name, _), = plan.layout
        return [dumps({name: r[0]}) for r in rows]
    cuts = []
    position = 0
    for name, size in plan.layout:
        cuts.append((name, position, size))
        position += max(size, 1)
    return [dumps({name: (r[a] if size == 0 else r[a:a + size]) for name, a, size in cuts}) for r in rows]



def _rate_of(table_hz: float | None, clock_hz: float | None) -> float:
    """A clock's sample rate: its table's (a time column), else the map's ``rate_hz`` (one is set)."""
    rate = table_hz or clock_hz
    if rate is None:
        raise MapError("a clock has neither a time column nor rate_hz")
    return float(rate)


def import_recording(
    data: Sequence[str | Path],
    rig: RigDescription | str | Path,
    channel_map: ChannelMap | str | Path,
    out: str | Path,
) -> ImportReport:
    """Write the recording ``out`` from the DATA files ``data`` as ``channel_map`` says.

    Parameters
    ----------
    data : sequence of paths
        The DAQ files (formats of :func:`shm_service.formats.tables.read_table`); each read by a clock.
    rig : RigDescription or path
        The rig description (``.json``/``.toml``): every topic of the map must be one of its sensors'.
    channel_map : ChannelMap or path
        The map, or its TOML file.
    out : path
        The recording to write (written to ``OUT.part`` first, then renamed: a failed import leaves
        no partial recording).

    Returns
    -------
    ImportReport

    Raises
    ------
    MapError
        For a map that does not fit the rig (a topic the rig does not declare, a field the topic
        lacks, a rig ``axes`` list the map does not fill) or the files (an unknown column, a clock
        whose rate disagrees with the file's time column).
    TableError
        For a file that cannot be read (a non-uniform time column, arrays of different lengths, ...).
    RigError, FileNotFoundError
        For a bad rig description or a missing file.
    """
    paths, rig, channel_map, map_text, source, out = _import_inputs(data, rig, channel_map, out)
    plans = _topic_plans(channel_map, rig, source)
    files = _resolve_files(channel_map, paths, source)

    tables, times = _read_clocks(channel_map, plans, files, source)
    # values per topic: SI = scale · value + offset; unfilled IMU fields 0.0; a sample is written
    # when every column of its topic is valid (the table's rejections, then the kind's limits)
    report_topics: dict[str, TopicImport] = {}
    streams: list[tuple[str, np.ndarray, list[bytes]]] = []
    axes_written: dict[str, list[str]] = {}
    for topic, plan in sorted(plans.items()):
        info, keep, values = _import_topic(plan, tables[plan.clock], channel_map.limits)
        if plan.title == "shm.Imu":
            axes_written[topic] = [a for a in _IMU_FIELDS if a not in info.zero_filled]
        report_topics[topic] = info
        streams.append((topic, times[plan.clock][keep], _payloads(plan, values[keep])))
    rig_doc = _rig_document(rig, axes_written)
    clocks_report = {
        name: ClockImport(str(files[name]), tables[name].format, int(tables[name].data.shape[0]),
                          _rate_of(tables[name].fs_hz, channel_map.clocks[name].rate_hz),
                          channel_map.clocks[name].start_time_ns(), int(times[name][0]), int(times[name][-1]))
        for name in channel_map.clocks
    }
    unused = _unused_columns(channel_map, plans, tables, files)
    metadata = _import_metadata(paths, tables, channel_map, map_text, report_topics)

    partial = out.with_name(out.name + ".part")
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with RecordingWriter(partial, rig_doc, metadata=metadata) as writer:
            _write_merged(writer, streams)
        os.replace(partial, out)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    declared = sorted(rig.sensor_by_topic())
    return ImportReport(str(out), report_topics, clocks_report, unused, [t for t in declared if t not in plans])


def _import_inputs(data: Sequence[str | Path], rig: RigDescription | str | Path, channel_map: ChannelMap | str | Path,
                   out: str | Path) -> tuple[list[Path], RigDescription, ChannelMap, str | None, str, Path]:
    """``import_recording``'s arguments checked and loaded: the files, rig, map (and its text, and
    what to call it in messages) and the output path."""
    paths = [Path(p) for p in data]
    if not paths:
        raise MapError("no DATA file given")
    for p in paths:
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such file")
    map_text = None
    if isinstance(channel_map, (str, Path)):
        source = str(channel_map)
        channel_map, map_text = load_channel_map(channel_map)
    else:
        source = "channel map"
    if not isinstance(rig, RigDescription):
        rig = load_rig(rig)
    out = Path(out)
    if any(out.resolve() == p.resolve() for p in paths):
        raise MapError(f"--out {out} is one of the DATA files")
    return paths, rig, channel_map, map_text, source, out


_IMU_FIELDS = [f"{f}_{a}" for f in ("accel", "gyro") for a in _AXES]


def _read_clocks(channel_map: ChannelMap, plans: dict, files: dict, source: str) -> tuple[dict[str, Table], dict[str, np.ndarray]]:
    """Each clock's table of its columns and its log times (a file read once per clock: other
    clocks' arrays may differ in length)."""
    tables: dict[str, Table] = {}
    times: dict[str, np.ndarray] = {}
    for name, clock in channel_map.clocks.items():
        where = f"{source}: clocks.{_quote(name)} ({files[name]})"
        columns = list(dict.fromkeys(slot.column for plan in plans.values() if plan.clock == name for slot in plan.slots))
        if not columns:
            raise MapError(f"{where}: no column uses this clock")
        try:
            table = read_table(files[name], fs=clock.rate_hz, channels=columns, time_column=clock.column,
                               time_unit=clock.unit, nonfinite="keep")
        except TableError as exc:
            if exc.channel is not None and exc.channel != clock.column:
                keys = [s.key for p in plans.values() for s in p.slots if s.column == exc.channel]
                raise MapError(f"{source}: columns.{_quote(keys[0] if keys else exc.channel)}: {exc}") from None
            if exc.channel is not None:
                raise MapError(f"{where}: column={clock.column!r}: {exc}") from None
            raise TableError(f"{where}: {exc}") from None
        tables[name] = table
        times[name] = _log_times(clock, table, where)
    return tables, times


def _import_topic(plan: Any, table: Table, limits: Any) -> tuple[TopicImport, np.ndarray, np.ndarray]:
    """One topic's values (n, width) in SI from its columns, which samples to keep (every column
    valid: the table's rejections, then the kind's limits) and its report."""
    n = table.data.shape[0]
    values = np.zeros((n, plan.width))
    bad = np.zeros(n, dtype=bool)
    why = np.zeros(n, dtype=np.int8)  # the reason of a rejected sample: its first bad column's
    first: tuple[int, str] | None = None
    rejections = Rejections()
    rejections.line_of = table.rejections.line_of
    for slot in sorted(plan.slots, key=lambda s: s.offset):
        raw = table.data[:, table.channels.index(slot.column)]
        with np.errstate(over="ignore", invalid="ignore"):
            values[:, slot.offset] = slot.scale * raw + slot.bias
        column_bad = ~np.isfinite(raw)
        scaled_nonfinite = np.isfinite(raw) & ~np.isfinite(values[:, slot.offset])
        rejections.merge(table.rejections.only(slot.column), {slot.column: slot.key})
        if scaled_nonfinite.any():
            rejections.add(slot.key, "nonfinite", np.flatnonzero(scaled_nonfinite))
        low, high, text = _limit_of(plan.kind, slot.axis, limits)
        with np.errstate(invalid="ignore"):
            beyond = np.isfinite(values[:, slot.offset]) & ((values[:, slot.offset] < low) | (values[:, slot.offset] > high))
        if beyond.any():
            rejections.add(slot.key, "implausible", np.flatnonzero(beyond), limit=text)
        column_bad |= scaled_nonfinite | beyond
        codes = table.codes[:, table.channels.index(slot.column)].copy() if table.codes is not None else np.zeros(n, np.int8)
        codes[scaled_nonfinite] = REASONS.index("nonfinite") + 1
        codes[beyond] = REASONS.index("implausible") + 1
        why = np.where((why == 0) & column_bad, codes, why)
        if column_bad.any():
            row = int(np.argmax(column_bad))
            if first is None or row < first[0]:
                first = (row, slot.column)
            bad |= column_bad
    info = TopicImport(plan.clock, [s.key for s in plan.slots])
    if plan.title == "shm.Imu":
        mapped = {s.axis for s in plan.slots}
        info.zero_filled = [a for a in _IMU_FIELDS if a not in mapped]
    keep = ~bad
    info.messages = int(keep.sum())
    info.rejected = int(bad.sum())
    counts = np.bincount(why[bad], minlength=len(REASONS) + 1)
    info.reasons = {REASONS[c - 1]: int(counts[c]) for c in range(1, len(REASONS) + 1) if counts[c]}
    info.by_column = rejections.as_dict()["channels"]
    if first is not None:
        info.first_rejected_row, info.first_rejected_column = first
    return info, keep, values


def _rig_document(rig: RigDescription, axes_written: dict[str, list[str]]) -> dict:
    """The rig as given (its own keys only), with the axes of every partly filled IMU."""
    rig_doc = rig.model_dump(mode="json", exclude_unset=True)
    for sensor in rig_doc["sensors"]:
        topic = f"/imu/{sensor['name']}" if sensor["kind"] == "imu" else None
        if topic in axes_written and "axes" not in sensor and len(axes_written[topic]) < 6:
            sensor["axes"] = axes_written[topic]
    return rig_doc


def _unused_columns(channel_map: ChannelMap, plans: dict, tables: dict[str, Table], files: dict) -> dict[str, list[str]]:
    """Per file, its numeric columns that no topic and no clock reads."""
    used = {s.column for p in plans.values() for s in p.slots}
    clock_columns = {c.column for c in channel_map.clocks.values() if c.column}
    unused: dict[str, list[str]] = {}
    for name, table in tables.items():
        left = [c for c in table.other_channels if c not in used and c not in clock_columns]
        if left:
            unused.setdefault(str(files[name]), [])
            unused[str(files[name])] += [c for c in left if c not in unused[str(files[name])]]
    return unused


def _import_metadata(paths: list[Path], tables: dict[str, Table], channel_map: ChannelMap, map_text: str | None,
                     report_topics: dict[str, TopicImport]) -> dict:
    return {"import": {
        "tool": "shm import",
        "files": json.dumps([str(p.name) for p in paths]),
        "formats": json.dumps({name: t.format for name, t in tables.items()}),
        "map": map_text if map_text is not None else json.dumps(channel_map.model_dump(mode="json")),
        "rejected_nonfinite": json.dumps({t: r.rejected for t, r in report_topics.items()}),
        "rejected": json.dumps({t: {"samples": r.rejected, "reasons": r.reasons} for t, r in report_topics.items()}),
        "zero_filled": json.dumps({t: r.zero_filled for t, r in report_topics.items() if r.zero_filled}),
        # the readers judge the recording's values by these (the map's [limits])
        "limits": channel_map.limits.model_dump_json(),
    }}


def _write_merged(writer: RecordingWriter, streams: list[tuple[str, np.ndarray, list[bytes]]]) -> None:
    """Write every topic's messages in log-time order (equal times in topic order)."""
    if not streams:
        return
    stamps = np.concatenate([s[1] for s in streams])
    which = np.repeat(np.arange(len(streams)), [len(s[1]) for s in streams])
    row = np.concatenate([np.arange(len(s[1])) for s in streams])
    order = np.lexsort((which, stamps))
    write = writer.write
    for k in order.tolist():
        topic, t, payloads = streams[which[k]]
        stamp = int(t[row[k]])
        write(topic, stamp, payloads[row[k]])
