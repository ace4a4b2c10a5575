"""Topics, JSON schemas and payload layouts of the recording contract (recording-format.md).

Every channel of a recording carries a ``jsonschema`` schema whose title names the payload type.
``PAYLOAD_FIELDS`` gives, per title, the payload keys in the order in which readers lay them out
as a row of numbers, and the size of each: a scalar, a fixed-length vector, a vector with one
entry per ``truth_stations`` entry of ``rig.json``, or a vector whose length is set by the
channel's first valid message (the estimator's state size).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final, Literal

__all__ = [
    "BEARING_TOPIC",
    "ESTIMATE_LOADS_TOPIC",
    "ESTIMATE_TOPIC",
    "IMU_BIAXIAL_COLUMNS",
    "IMU_PLANAR_COLUMNS",
    "NOMINAL_PERIOD_NS",
    "PAYLOAD_FIELDS",
    "PAYLOAD_FIELDS_BIAXIAL",
    "SCHEMAS",
    "TEMPERATURE_TOPIC",
    "TRUTH_TOPIC",
    "FieldSpec",
    "Kind",
    "RowLayout",
    "TopicInfo",
    "classify_topic",
    "payload_fields",
    "row_layout",
]

TRUTH_TOPIC: Final = "/truth/state"
ESTIMATE_TOPIC: Final = "/estimate/state"
#: The virtual loads of each estimate at the stations the recording's metadata "loads" names.
ESTIMATE_LOADS_TOPIC: Final = "/estimate/loads"
BEARING_TOPIC: Final = "/bearing/displacement"
TEMPERATURE_TOPIC: Final = "/env/temperature"

Kind = Literal["imu", "tof", "strain", "bearing", "temperature", "truth", "estimate"]


def _number(description: str) -> dict[str, Any]:
    return {"type": "number", "description": description}


def _vector(description: str, size: int | None = None) -> dict[str, Any]:
    schema: dict[str, Any] = {"type": "array", "items": {"type": "number"}, "description": description}
    if size is not None:
        schema["minItems"] = size
        schema["maxItems"] = size
    return schema


def _object(title: str, description: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": list(properties),
    }


_BODY_STATE = {
    "d": _number("horizontal position of the bearing D (zeta), m"),
    "h": _number("vertical position of the bearing D (eta), m"),
    "phi": _number("attitude of the body frame, rad (positive turns eta towards zeta)"),
    "e": _number("tip deflection Delta(L) in the body frame, m"),
}

#: The contract's schemas, by title.
SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    "shm.Imu": _object(
        "shm.Imu",
        "IMU sample in the sensor frame",
        {
            "accel": _vector("specific force [x, y, z], m/s^2", 3),
            "gyro": _vector("angular rate [x, y, z], rad/s", 3),
        },
    ),
    "shm.Distance": _object(
        "shm.Distance", "a distance sample", {"distance": _number("distance, m")}
    ),
    "shm.Strain": _object(
        "shm.Strain", "bending strain on the +zeta face", {"strain": _number("strain, m/m")}
    ),
    "shm.Temperature": _object(
        "shm.Temperature", "ambient temperature", {"celsius": _number("temperature, degC")}
    ),
    "shm.TruthState": _object(
        "shm.TruthState",
        "the simulated plant's exact state (simulated recordings only)",
        {
            **_BODY_STATE,
            "deflection": _vector("Delta(eta_k) in the body frame at truth_stations, m"),
            "curvature": _vector("d2 Delta / d eta2 (eta_k) at truth_stations, 1/m"),
        },
    ),
    "shm.EstimateState": _object(
        "shm.EstimateState",
        "the estimator's output",
        {
            **_BODY_STATE,
            "b": _vector("amplitudes of the unit deformations (dimensionless)"),
            "deflection": _vector("Delta(eta_k) in the body frame at truth_stations, m"),
            "curvature": _vector("d2 Delta / d eta2 (eta_k) at truth_stations, 1/m"),
            "covariance_diagonal": _vector("diagonal of the state covariance (units of the state squared)"),
        },
    ),
    "shm.EstimateLoads": _object(
        "shm.EstimateLoads",
        "virtual loads of an estimate at the stations of the recording's metadata 'loads' (stations_m, names)",
        {
            "strain": _vector("bending strain -c(eta) kappa(eta) on the +zeta face at the stations, m/m"),
            "moment_nm": _vector("bending moment EI(eta) kappa(eta) at the stations (reference temperature), N m"),
            "root_moment_nm": _number("bending moment at the support D, EI(0) kappa(0), N m (0 for a pinned support)"),
        },
    ),
}

FieldSize = int | Literal["stations", "free"]


@dataclass(frozen=True, slots=True)
class FieldSpec:
    """One payload key: ``size`` is 0 for a number, n for a vector of n numbers, ``"stations"``
    for one number per truth station, ``"free"`` for a length fixed by the channel's first valid
    message."""

    name: str
    size: FieldSize


_STATE_FIELDS = (FieldSpec("d", 0), FieldSpec("h", 0), FieldSpec("phi", 0), FieldSpec("e", 0))

#: Payload layout by schema title: the row of a sample is the fields' values in this order.
PAYLOAD_FIELDS: Final[dict[str, tuple[FieldSpec, ...]]] = {
    "shm.Imu": (FieldSpec("accel", 3), FieldSpec("gyro", 3)),
    "shm.Distance": (FieldSpec("distance", 0),),
    "shm.Strain": (FieldSpec("strain", 0),),
    "shm.Temperature": (FieldSpec("celsius", 0),),
    "shm.TruthState": (*_STATE_FIELDS, FieldSpec("deflection", "stations"), FieldSpec("curvature", "stations")),
    "shm.EstimateState": (
        *_STATE_FIELDS,
        FieldSpec("b", "free"),
        FieldSpec("deflection", "stations"),
        FieldSpec("curvature", "stations"),
        FieldSpec("covariance_diagonal", "free"),
    ),
    "shm.EstimateLoads": (FieldSpec("strain", "free"), FieldSpec("moment_nm", "free"), FieldSpec("root_moment_nm", 0)),
}

_XI_FIELDS = (FieldSpec("e_xi", 0), FieldSpec("deflection_xi", "stations"), FieldSpec("curvature_xi", "stations"))
#: A biaxial beam's payloads (beam.bending = "biaxial"): the planar keys, then the ξ plane's
#: (recording-format.md, "Bending in two planes"); the titles not listed here are the same.
PAYLOAD_FIELDS_BIAXIAL: Final[dict[str, tuple[FieldSpec, ...]]] = {
    "shm.TruthState": (*PAYLOAD_FIELDS["shm.TruthState"], *_XI_FIELDS),
    "shm.EstimateState": (*PAYLOAD_FIELDS["shm.EstimateState"], FieldSpec("b_xi", "free"), *_XI_FIELDS),
}


def payload_fields(title: str, *, biaxial: bool = False) -> tuple[FieldSpec, ...]:
    """The payload keys of schema ``title`` in row order; ``biaxial``: a biaxial beam's (the ξ keys
    after the planar ones for the truth and the estimate). KeyError for an unknown title."""
    if biaxial and title in PAYLOAD_FIELDS_BIAXIAL:
        return PAYLOAD_FIELDS_BIAXIAL[title]
    return PAYLOAD_FIELDS[title]

#: Nominal sample period (ns) of the kinds that have a fixed rate.
NOMINAL_PERIOD_NS: Final[dict[str, int]] = {
    "imu": 5_000_000,
    "strain": 5_000_000,
    "truth": 5_000_000,
    "tof": 30_000_000,
    "bearing": 30_000_000,
}


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """What a topic is: the kind of data, the sensor name (``None`` for the fixed topics whose
    sensor name comes from ``rig.json``, and for truth and estimate), and the schema title."""

    kind: Kind
    name: str | None
    title: str


_SENSOR_PREFIXES: Final[dict[str, tuple[Kind, str]]] = {
    "/imu/": ("imu", "shm.Imu"),
    "/tof/": ("tof", "shm.Distance"),
    "/strain/": ("strain", "shm.Strain"),
}

_FIXED_TOPICS: Final[dict[str, TopicInfo]] = {
    BEARING_TOPIC: TopicInfo("bearing", None, "shm.Distance"),
    TEMPERATURE_TOPIC: TopicInfo("temperature", None, "shm.Temperature"),
    TRUTH_TOPIC: TopicInfo("truth", None, "shm.TruthState"),
    ESTIMATE_TOPIC: TopicInfo("estimate", None, "shm.EstimateState"),
    ESTIMATE_LOADS_TOPIC: TopicInfo("estimate", None, "shm.EstimateLoads"),
}


def classify_topic(topic: str) -> TopicInfo | None:
    """The contract's meaning of ``topic``, or ``None`` for a topic the contract does not know.

    Examples
    --------
    >>> from contract import classify_topic
    >>> classify_topic("/imu/s1")
    TopicInfo(kind='imu', name='s1', title='shm.Imu')
    >>> classify_topic("/bearing/displacement").title
    'shm.Distance'
    >>> classify_topic("/camera/front") is None
    True
    """
    fixed = _FIXED_TOPICS.get(topic)
    if fixed is not None:
        return fixed
    for prefix, (kind, title) in _SENSOR_PREFIXES.items():
        if topic.startswith(prefix):
            name = topic[len(prefix):]
            if name and "/" not in name:
                return TopicInfo(kind, name, title)
    return None


@dataclass(frozen=True, slots=True)
class RowLayout:
    """Where each payload key of a schema sits in a row of numbers (``PAYLOAD_FIELDS`` order).

    ``widths`` holds per field its number of columns (1 for a number, n for a vector of n, the
    ``"stations"`` and ``"free"`` lengths resolved); ``row_layout`` builds it.
    """

    title: str
    widths: tuple[int, ...]
    biaxial: bool = False

    @property
    def fields(self) -> tuple[FieldSpec, ...]:
        return payload_fields(self.title, biaxial=self.biaxial)

    @property
    def width(self) -> int:
        return sum(self.widths)

    def columns(self, name: str) -> slice:
        """The columns of payload key ``name`` (one column for a number)."""
        start = 0
        for spec, width in zip(self.fields, self.widths):
            stop = start + width
            if spec.name == name:
                return slice(start, stop)
            start = stop
        raise KeyError(f"{self.title} has no payload key {name!r}; it has {[f.name for f in self.fields]}")

    def column(self, name: str, index: int = 0) -> int:
        """The column of entry ``index`` of payload key ``name``."""
        cols = self.columns(name)
        if not 0 <= index < cols.stop - cols.start:
            raise IndexError(f"{self.title}.{name} has {cols.stop - cols.start} entries, no index {index}")
        return cols.start + index

    def names(self) -> tuple[str, ...]:
        """Column names: a number's key, or ``key[i]`` for the entries of a vector."""
        out: list[str] = []
        for spec, width in zip(self.fields, self.widths):
            out.extend([spec.name] if spec.size == 0 else [f"{spec.name}[{i}]" for i in range(width)])
        return tuple(out)


def row_layout(title: str, *, stations: int | None = None, free: dict[str, int] | None = None,
               biaxial: bool = False) -> RowLayout:
    """The row layout of schema ``title`` with ``stations`` truth stations and the ``free``
    lengths (by key) of the estimate's vectors; ``biaxial``: a biaxial beam's payload (its ξ keys).
    Raises KeyError for an unknown title and ValueError when a size the schema needs is not given."""
    if title not in PAYLOAD_FIELDS:
        raise KeyError(f"unknown payload schema {title!r}; known: {sorted(PAYLOAD_FIELDS)}")
    free = dict(free or {})
    widths: list[int] = []
    for spec in payload_fields(title, biaxial=biaxial):
        if spec.size == "stations":
            if stations is None or stations < 0:
                raise ValueError(f"{title}.{spec.name} has one entry per truth station: give {stations=} >= 0")
            widths.append(int(stations))
        elif spec.size == "free":
            if free.get(spec.name, -1) < 0:
                raise ValueError(f"{title}.{spec.name} has a free length: give free={{{spec.name!r}: n}}")
            widths.append(int(free.pop(spec.name)))
        elif isinstance(spec.size, int):
            widths.append(max(spec.size, 1))
        else:
            raise ValueError(f"{title}.{spec.name}: unknown field size {spec.size!r}")
    if free:
        raise ValueError(f"{title} has no free-length keys {sorted(free)}")
    return RowLayout(title, tuple(widths), biaxial)


_IMU = row_layout("shm.Imu")
#: Columns of an IMU row that the planar model uses: f_x, f_y (specific force in the beam's plane,
#: m/s²) and ω_z (rate about the axis normal to the plane, rad/s).
IMU_PLANAR_COLUMNS: Final[tuple[int, int, int]] = (_IMU.column("accel", 0), _IMU.column("accel", 1), _IMU.column("gyro", 2))
#: A biaxial beam's IMU columns: the planar three, then accel z and gyro y (the ξ plane's).
IMU_BIAXIAL_COLUMNS: Final[tuple[int, int, int, int, int]] = (*IMU_PLANAR_COLUMNS, _IMU.column("accel", 2), _IMU.column("gyro", 1))
