"""Sensor faults injected into a live source, for fault campaigns and for operators who want to
see their alarms and dashboards react: ``[sim] faults = ["spike:/imu/D.accel_y@300+1:100"]``.

A fault spec is ``KIND:TOPIC[.FIELD]@START+DURATION[:VALUE]`` with START and DURATION in seconds
of the source's data time (after its first sample):

=========  =================================================================================
silence    the topic delivers nothing
nan        its readings are NaN
spike      VALUE is added to FIELD (an IMU's accel_x, accel_y, accel_z, gyro_x, gyro_y, gyro_z;
           the single reading of other sensors)
stuck      it repeats the reading it had when the fault began
clock      its stamps are shifted by VALUE seconds (a clock that jumps and comes back)
=========  =================================================================================

The faults act on the samples as the source delivers them, before any of the service's checks:
what the service then sees is what a faulty sensor would hand it.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass

import numpy as np

from contract import PAYLOAD_FIELDS, classify_topic

__all__ = ["FAULT_KINDS", "Fault", "apply_faults", "parse_fault"]

FAULT_KINDS = ("silence", "nan", "spike", "stuck", "clock")
_NS = 1_000_000_000
_SPEC = re.compile(r"^(?P<kind>[a-z]+):(?P<topic>/[A-Za-z0-9_/]+?)(?:\.(?P<field>[a-z_]+))?@(?P<start>[0-9.eE+-]+?)"
                   r"\+(?P<duration>[0-9.eE+-]+?)(?::(?P<value>[-+0-9.eE]+))?$")


@dataclass(frozen=True)
class Fault:
    kind: str
    topic: str
    start_s: float
    duration_s: float
    value: float | None = None
    column: int | None = None  # the payload row column a spike acts on

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s


def _imu_columns() -> dict[str, int]:
    out, k = {}, 0
    for spec in PAYLOAD_FIELDS["shm.Imu"]:
        for axis in "xyz":
            out[f"{spec.name}_{axis}"] = k
            k += 1
    return out


def parse_fault(spec: str) -> Fault:
    """A fault from its spec (see the module); raises ValueError naming what is wrong."""
    m = _SPEC.match(spec.strip())
    if m is None:
        raise ValueError(f"fault {spec!r} must be KIND:TOPIC[.FIELD]@START+DURATION[:VALUE], "
                         f"e.g. spike:/imu/D.accel_y@300+1:100")
    kind, topic, field, value = m["kind"], m["topic"], m["field"], m["value"]
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault {spec!r}: kind {kind!r} must be one of {', '.join(FAULT_KINDS)}")
    info = classify_topic(topic)
    if info is None or info.kind not in ("imu", "tof", "strain", "bearing", "temperature"):
        raise ValueError(f"fault {spec!r}: {topic!r} is not a sensor topic of the recording contract")
    try:
        start, duration = float(m["start"]), float(m["duration"])
        number = None if value is None else float(value)
    except ValueError:
        raise ValueError(f"fault {spec!r}: START, DURATION and VALUE must be numbers") from None
    if not (math.isfinite(start) and start >= 0 and math.isfinite(duration) and duration > 0):
        raise ValueError(f"fault {spec!r}: START must be >= 0 and DURATION > 0 (seconds)")
    column = None
    if kind in ("spike", "clock"):
        if number is None or not math.isfinite(number):
            raise ValueError(f"fault {spec!r}: a {kind} needs a finite VALUE ({'added' if kind == 'spike' else 'shift, s'})")
    elif number is not None:
        raise ValueError(f"fault {spec!r}: a {kind} takes no VALUE")
    if kind == "spike":
        if info.kind == "imu":
            columns = _imu_columns()
            if field not in columns:
                raise ValueError(f"fault {spec!r}: an IMU spike names its field, one of {', '.join(columns)}")
            column = columns[field]
        elif field is not None:
            raise ValueError(f"fault {spec!r}: a {info.kind} sensor has one reading (no .FIELD)")
        else:
            column = 0
    elif field is not None:
        raise ValueError(f"fault {spec!r}: only a spike names a FIELD")
    return Fault(kind, topic, start, duration, number, column)


def apply_faults(faults: list[Fault] | tuple[Fault, ...], topic: str, times_s: np.ndarray, stamps_ns: np.ndarray,
                 values: np.ndarray, state: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, Counter]:
    """The samples of one block of ``topic`` as the faults make them.

    Parameters
    ----------
    faults : the faults (those of other topics are ignored).
    topic : the block's topic.
    times_s : (n,) data time of the samples since the source's first one, s.
    stamps_ns, values : (n,) stamps and (n, k) readings as the sensor would deliver them.
    state : per-source memory between blocks (a stuck reading, the newest stamp per topic); pass
        the same dict for every block of a source.

    Returns
    -------
    kept : (m,) indices of the samples delivered (into the block).
    stamps, values : (m,) stamps and (m, k) readings delivered (copies when anything changed). After
        a clock fault the stamps may go back in time: the service orders and judges them.
    dropped : Counter (empty: kept for sources that drop samples themselves).
    """
    dropped: Counter = Counter()
    kept = np.arange(len(times_s))
    stamps, values = stamps_ns, values
    mine = [f for f in faults if f.topic == topic]
    if mine:
        stamps, values = stamps_ns.copy(), np.array(values, dtype=float)
        keep = np.ones(len(times_s), dtype=bool)
        for f in mine:
            hit = (times_s >= f.start_s) & (times_s < f.end_s)
            key = (topic, f.kind, f.start_s)
            if f.kind == "stuck":
                if hit.any() and key not in state:
                    state[key] = values[np.argmax(hit)].copy()
                if key in state:
                    values[hit] = state[key]
            if not hit.any():
                continue
            if f.kind == "silence":
                keep &= ~hit
            elif f.kind == "nan":
                values[hit] = np.nan
            elif f.kind == "spike":
                values[hit, f.column] += f.value
            elif f.kind == "clock":
                assert f.value is not None, "parse_fault gives a clock fault its shift"
                stamps[hit] += int(round(f.value * _NS))
            elif f.kind != "stuck":
                raise ValueError(f"unknown fault kind {f.kind!r}")
        kept, stamps, values = kept[keep], stamps[keep], values[keep]
    return kept, stamps, values, dropped
