"""Settings of ``shm serve``: one typed, closed model, read from one TOML file and overridden
by command-line flags. Secrets (the API token) come from a file or from the environment, which
is injectable (tests pass a dict).

The configuration is made of the parts' own settings: a section is the settings model of the part
it configures, defined in that part's package (``[archive]`` the archive's, ``[retention]``
retention's, ``[notify]`` the notifier's, ``[sim]``, ``[source]`` and ``[mqtt]`` the sources', ``[source]``
made of the merge's and the checks'; ``[estimator]`` extends the estimate stage's), so each key
has one definition and one default, and the parts never import this module."""

from __future__ import annotations

import ipaddress
import os
import re
import tomllib
from collections.abc import Mapping
from copy import copy
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from analytics import AnalysisConfig
from contract import is_loopback
from estimator import StreamingSettings

from .alarms._notify import NotifySettings
from .sources._settings import SOURCE_SPEC, MqttSettings, SimSettings, SourceSettings, check_spec
from .stages._archive import ArchiveSettings
from .stages._commit import CommitSettings
from .stages._estimate import EstimateSettings
from .storage._retention import RetentionSettings
from .storage._url import check_postgres_url, is_postgres_url, redact

__all__ = [
    "AlarmSettings",
    "DashboardSettings",
    "EstimatorSettings",
    "NodeSettings",
    "ServerSettings",
    "ServiceSettings",
    "SettingsError",
    "StructureSettings",
    "load_settings",
    "render_toml",
    "resolve_token",
]

TOKEN_ENV = "SHM_TOKEN"


class SettingsError(ValueError):
    """Invalid configuration (the message names the key)."""


class _Closed(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)



def _key_of(model: type[BaseModel], name: str) -> Any:
    """A part's field as a key of another section, with its definition (default, bounds and
    description): a key users know under another name has one source of truth."""
    return copy(model.model_fields[name])


class ServerSettings(_Closed):
    """The HTTP API."""

    host: str = Field("127.0.0.1", description="address to bind; any other than loopback requires a token for every request")
    port: int = Field(8600, ge=0, le=65535, description="HTTP API port (0: a free port)")
    token_file: str | None = Field(None, description="file holding the API token (first line); else the environment variable SHM_TOKEN")
    max_body_bytes: int = Field(64 * 1024, ge=1024, description="largest request body, bytes, except ingest")
    max_ingest_bytes: int = Field(8 * 1024 * 1024, ge=1024, description="largest ingest request body, bytes")
    max_ingest_messages: int = Field(100_000, ge=1, description="most messages in one ingest request")
    ingest_wait_s: float = Field(5.0, gt=0, description="how long an ingest request waits for room in the pipeline before 503")
    allowed_hosts: tuple[str, ...] = Field(
        (), description="host names (or addresses) the API answers to in the Host header besides loopback and its own "
        "address, e.g. ['shm.example.org', '*.plant.local']; others get 421 (against DNS rebinding); ['*']: any")
    auth_failures_per_minute: int = Field(
        10, ge=1, le=10_000, description="wrong tokens accepted from one client address per minute; more are answered 429")

    @field_validator("allowed_hosts")
    @classmethod
    def _allowed_hosts(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        out = []
        for name in value:
            host = name.strip().lower().rstrip(".")
            if host.startswith("[") and host.endswith("]"):
                host = host[1:-1]
            label = host[2:] if host.startswith("*.") else host
            if host != "*" and (not label or any(c in label for c in " /\\@?#:*") and not _is_ip(label)):
                raise ValueError(f"allowed_hosts entry {name!r} must be a host name or address without scheme or port "
                                 "(e.g. 'shm.example.org', '*.plant.local', '10.0.0.5')")
            out.append(host)
        return tuple(out)

    @field_validator("host")
    @classmethod
    def _host(cls, value: str) -> str:
        if value in ("localhost", ""):
            return "127.0.0.1"
        try:
            ipaddress.ip_address(value)
        except ValueError:
            raise ValueError(f"host {value!r} must be an IP address (e.g. 127.0.0.1 or 0.0.0.0)") from None
        return value

    @property
    def loopback(self) -> bool:
        return is_loopback(self.host)


def _is_ip(value: str) -> bool:
    try:
        ipaddress.ip_address(value)
    except ValueError:
        return False
    return True


class DashboardSettings(_Closed):
    """The live 3-D dashboard (package ``web``), in the same process."""

    enabled: bool = Field(True, description="start the dashboard")
    host: str = Field("127.0.0.1", description="address of the dashboard")
    port: int = Field(8080, ge=0, le=65535, description="dashboard port (0: a free port)")
    estimate_hz: float = Field(15.0, ge=1, le=100, description="rate of estimate pushes, Hz (decimated)")

    @property
    def loopback(self) -> bool:
        return is_loopback(self.host)


class EstimatorSettings(EstimateSettings):
    """The IMMS estimator (model from the rig description).

    The estimate stage's settings (``EstimateSettings``) and the model's sensors."""

    peripheral: Literal["gyro", "acc"] = Field("gyro", description="kinematic model of the peripheral IMUs")
    modes: int = Field(4, ge=1, le=5, description="unit deformations, Γ")
    modes_xi: int | None = Field(None, ge=1, le=5, description="unit deformations in ξ of a biaxial beam, Γξ (None: as modes; "
                                 "ignored for a planar beam)")
    imus: int = Field(4, ge=0, le=16, description="peripheral IMUs (chosen by effective independence)")
    tofs: int = Field(4, ge=0, le=16, description="ToF sensors")
    gauges: int = Field(4, ge=0, le=16, description="strain gauges")


class AlarmSettings(_Closed):
    """Alarms from the analytics' control charts. Their hysteresis is the engine's (``shm analyze``
    raises the same alarms on the same data): ``analytics.hold_windows`` and ``analytics.clear_windows``;
    the two keys here, when set, override those for the service."""

    raise_windows: int | None = Field(None, ge=1, le=100, description="consecutive windows at or beyond a level before it is raised "
                                      "(default: analytics.hold_windows)")
    clear_windows: int | None = Field(None, ge=1, le=100, description="consecutive windows below analytics.clear_sigma before an alarm "
                                      "clears (default: analytics.clear_windows)")
    notify_levels: tuple[Literal["warning", "alarm"], ...] = Field(("warning", "alarm"), description="levels that notify")
    notify_cleared: bool = Field(True, description="notify when an alarm clears")
    repeat_interval_s: float | None = Field(
        4 * 3600.0, gt=0, description="re-notify an alarm that still fires after this long, wall-clock s (like "
        "Alertmanager's repeat_interval; None: never)")
    stale_after_s: float = Field(
        900.0, gt=0, description="the active alarms of a source that delivered no data for this long are marked stale, "
        "wall-clock s")
    notify_stale: bool = Field(True, description="notify when an alarm goes stale (its source went silent)")


class StorageSettings(_Closed):
    """Where the service stores what it computes: the SQLite file ``db`` (the default) or, with
    ``url``, a PostgreSQL database that the nodes of a fleet share."""

    url: str | None = Field(
        None, description="PostgreSQL database, postgresql://USER[:PASSWORD]@HOST:PORT/DB (the server's other options as "
        "URL query parameters); unset: the SQLite file db")

    @field_validator("url")
    @classmethod
    def _url(cls, value: str | None) -> str | None:
        return None if value is None else check_postgres_url(value, "storage.url")


class NodeSettings(_Closed):
    """The nodes of a fleet (``shm serve --node NAME`` on several machines with this configuration and
    one PostgreSQL database, storage.url): they share the structures through leases in the database."""

    lease_s: float = Field(
        15.0, ge=3, le=3600, description="how long a node's lease of a structure holds without renewal, s (renewed every "
        "third of it): a node that dies loses its structures to the others within this")


class StructureSettings(_Closed):
    """One structure of a fleet (``[[structures]]``). Its tables ``sim``, ``estimator``,
    ``analytics`` and ``alarms`` override the keys of the service's tables of the same name for
    this structure only; ``source.speed`` (``--speed``) and everything else are the service's."""

    id: str = Field(..., min_length=1, max_length=64, pattern=r"^[a-z0-9-]+$",
                    description="structure id ([a-z0-9-]): the source id of its trend rows, alarms and notifications")
    source: str = Field("sim", description=SOURCE_SPEC)
    rig: str | None = Field(None, description="rig description (.json/.toml) for ingest and mqtt, or to replace a recording's rig.json")
    sim: dict[str, Any] = Field(default_factory=dict, description="keys of [sim] for this structure (e.g. seed)")
    estimator: dict[str, Any] = Field(default_factory=dict, description="keys of [estimator] for this structure")
    analytics: dict[str, Any] = Field(default_factory=dict, description="keys of [analytics] for this structure")
    alarms: dict[str, Any] = Field(default_factory=dict, description="keys of [alarms] for this structure")

    @field_validator("source")
    @classmethod
    def _spec(cls, value: str) -> str:
        return check_spec(value)


class ServiceSettings(_Closed):
    """Everything ``shm serve`` reads. Every key has a default; a TOML file sets some of them."""

    data_dir: str | None = Field(
        None, description="directory of all of the service's files: db and archive.directory default to paths under it "
        "(default: the directory of db when db is given, else ./var)")
    db: str | None = Field(None, description="SQLite database (trends, baseline, alarms, outbox); default DATA_DIR/shm.sqlite "
                           "(with storage.url: that URL)")
    server: ServerSettings = ServerSettings()
    dashboard: DashboardSettings = DashboardSettings()
    source: SourceSettings = SourceSettings()
    sim: SimSettings = SimSettings()
    estimator: EstimatorSettings = EstimatorSettings()
    analytics: AnalysisConfig = AnalysisConfig()
    archive: ArchiveSettings = ArchiveSettings()
    retention: RetentionSettings = RetentionSettings()
    alarms: AlarmSettings = AlarmSettings()
    notify: NotifySettings = NotifySettings()
    mqtt: MqttSettings = MqttSettings()
    nodes: NodeSettings = NodeSettings()
    storage: StorageSettings = StorageSettings()
    storage_sync: Literal["normal", "full"] = Field(
        "normal", description="SQLite synchronous mode of transactions that write only trend rows and state: normal "
        "survives a process crash, full also a power loss")
    storage_alarm_sync: Literal["normal", "full"] = Field(
        "full", description="SQLite synchronous mode of transactions that write alarms, alarm events or the "
        "notification outbox (full: they survive a power loss)")
    # the commit stage's retry under the key users know (one definition: CommitSettings.retry_s)
    storage_retry_s: float = _key_of(CommitSettings, "retry_s")
    pipeline_threads: int = Field(
        3, ge=1, le=64, description="threads of a (worker) process that step its structures' pipelines, round-robin "
        "(each structure's data and analysis lanes; its source has a thread of its own)")
    stop_drain_s: float = Field(
        4.0, ge=0, le=600, description="on stop (SIGTERM), how long a structure goes on estimating and analysing its "
        "backlog; what is left then is not analysed (its raw samples are in the recording when it records them), so a "
        "stop under a backlog ends within seconds, s")
    queue_batches: int = Field(8, ge=2, le=10_000, description="bounded queue between source and pipeline, batches (a batch is at most ~10 s of data or 2 MB of a file)")
    log_level: Literal["debug", "info", "warning", "error"] = Field("info", description="log level")
    workers: Annotated[int, Field(ge=1, le=64)] | Literal["auto"] = Field(
        "auto", description="worker processes hosting the structures of a fleet, each every n-th structure on the "
        "one database (one process holds one GIL): \"auto\" one per core (at most one per structure), 1: all in this "
        "process")
    structures: tuple[StructureSettings, ...] = Field(
        (), description="a fleet: the structures this service monitors ([[structures]] tables); empty: the one structure "
        "of [source]")

    @model_validator(mode="after")
    def _paths(self) -> "ServiceSettings":
        # One data directory holds everything; the database and the recordings default to it. The
        # resolved paths are stored, so --print-config shows where the files really go.
        if self.storage.url is None and is_postgres_url(self.db):  # --db postgresql://...: the same as storage.url
            object.__setattr__(self, "storage", StorageSettings(url=check_postgres_url(str(self.db), "db")))
        url = self.storage.url
        if url is not None and self.db is not None and self.db != url:
            raise ValueError(f"db={self.db!r} and storage.url={redact(url)!r} are both given: the service stores in one "
                             "database (leave db out with a PostgreSQL url)")
        local = self.db if self.db and url is None else None
        data_dir = self.data_dir or (str(Path(local).parent) if local else "var")
        object.__setattr__(self, "data_dir", data_dir)
        if url is not None:  # every user of the database opens it by settings.db: the URL
            object.__setattr__(self, "db", url)
        elif self.db is None:
            object.__setattr__(self, "db", str(Path(data_dir) / "shm.sqlite"))
        if self.archive.directory is None:
            object.__setattr__(self, "archive", self.archive.model_copy(update={"directory": str(Path(data_dir) / "recordings")}))
        if self.retention.recordings_max_gb * 1e3 < 2 * self.archive.rotate_mb:
            raise ValueError(f"retention.recordings_max_gb={self.retention.recordings_max_gb} must hold at least two files of "
                             f"archive.rotate_mb={self.archive.rotate_mb} (the one being written is never deleted)")
        takers = [s.id for s in self.structures if s.source == "mqtt"] or (
            [] if self.structures or self.source.kind != "mqtt" else [self.source.id or "mqtt"])
        if takers and self.mqtt.url is None:
            raise ValueError(f"mqtt.url must be set: {'structure(s) ' + str(takers) if self.structures else 'the source'} "
                             "take their data from the broker (source = \"mqtt\")")
        if self.structures:
            ids = [s.id for s in self.structures]
            twice = sorted({i for i in ids if ids.count(i) > 1})
            if twice:
                raise ValueError(f"structures: the id(s) {twice} appear more than once (each structure needs its own id)")
            given = sorted(k for k in ("spec", "id", "rig") if k in self.source.model_fields_set)
            if given:
                raise ValueError(f"source.{given[0]} cannot be set with [[structures]]: each structure sets its own "
                                 "source, id and rig in its table")
            for structure in self.structures:
                self.for_structure(structure)  # every override is checked now, not when the structure starts
        return self

    @property
    def lock_path(self) -> str:
        """The local file the service's locks and worker records sit beside: the SQLite file
        ``db``, or for a PostgreSQL ``storage.url`` a name in ``data_dir`` for that database (the
        nodes sharing it are fenced by their leases in it, not by these files)."""
        if self.storage.url is None:
            return str(self.db)
        parts = urlsplit(self.storage.url)
        name = "-".join(str(x) for x in (parts.hostname, parts.port or 5432, parts.path.lstrip("/")))
        return str(Path(str(self.data_dir)) / f"postgresql-{re.sub(r'[^A-Za-z0-9._-]', '_', name)}")

    @property
    def worker_count(self) -> int:
        """The worker processes of the fleet (``workers``; "auto": one per core this process may run
        on, at most one per structure); 1 without a fleet."""
        if not self.structures:
            return 1
        if self.workers != "auto":
            return int(self.workers)
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        return max(1, min(cores, len(self.structures), 64))

    @property
    def db_path(self) -> str:
        """The database file: ``db``, which the validation resolved against ``data_dir``."""
        if self.db is None:
            raise SettingsError("db is not resolved (load the settings through ServiceSettings)")
        return self.db

    @property
    def fleet(self) -> bool:
        """True when the service monitors a list of structures (``[[structures]]``)."""
        return bool(self.structures)

    def for_structure(self, structure: StructureSettings) -> "ServiceSettings":
        """The settings of one structure of the fleet: these settings with the structure's source,
        id and rig, and its tables over the service's (only the keys set are carried, so defaults
        capped to the rig stay defaults)."""
        data = self.model_dump(exclude_unset=True, exclude={"structures"})
        data["data_dir"], data["db"] = self.data_dir, self.db
        data.setdefault("archive", {})["directory"] = self.archive.directory
        source = data.setdefault("source", {})
        source.update({"spec": structure.source, "id": structure.id})
        if structure.rig is not None:
            source["rig"] = structure.rig
        for table in ("sim", "estimator", "analytics", "alarms"):
            override = getattr(structure, table)
            if override:
                data[table] = _merge(data.get(table, {}), override)
        try:
            return ServiceSettings.model_validate(data)
        except ValidationError as exc:
            raise ValueError(f"structure {structure.id!r}: {_message(exc)}") from None

    def streaming_settings(self) -> StreamingSettings:
        """The streaming estimator's settings (``shm analyze --config`` of a raw file runs the same)."""
        return StreamingSettings(calibration_s=self.estimator.calibration_s, chunk_s=self.estimator.chunk_s)

    def engine_config(self) -> AnalysisConfig:
        """The analytics the engine runs: ``analytics`` with ``alarms.raise_windows``/``clear_windows``
        as its hysteresis when they are set (``shm analyze --config`` reads the same)."""
        a = self.alarms
        update = {k: v for k, v in (("hold_windows", a.raise_windows), ("clear_windows", a.clear_windows)) if v is not None}
        return self.analytics.model_copy(update=update) if update else self.analytics


def _merge(base: dict[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(dict(out[key]), value)
        else:
            out[key] = value
    return out


def _message(exc: ValidationError) -> str:
    return "; ".join(f"{'.'.join(str(p) for p in e['loc']) or '(top)'}: {e['msg']}" for e in exc.errors())


def load_settings(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> ServiceSettings:
    """Settings from the TOML file ``path`` (optional), then ``overrides`` (nested dict, e.g.
    from flags). Raises ``SettingsError`` naming the offending key."""
    data: dict[str, Any] = {}
    if path is not None:
        try:
            data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise SettingsError(f"config file {path} does not exist") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise SettingsError(f"config file {path}: {exc}") from None
    if overrides:
        data = _merge(data, overrides)
    try:
        return ServiceSettings.model_validate(data)
    except ValidationError as exc:
        raise SettingsError(_message(exc)) from None


def resolve_token(settings: ServiceSettings, environ: Mapping[str, str] | None = None) -> str | None:
    """The API token: the first line of ``server.token_file``, else ``SHM_TOKEN`` of the
    environment (``environ``, default ``os.environ``). ``None`` when neither is set."""
    env = os.environ if environ is None else environ
    if settings.server.token_file:
        try:
            text = Path(settings.server.token_file).read_text(encoding="utf-8")
        except OSError as exc:
            raise SettingsError(f"server.token_file: cannot read {settings.server.token_file}: {exc}") from None
        token = text.strip().splitlines()[0].strip() if text.strip() else ""
        if len(token) < 8:
            raise SettingsError("server.token_file: the token must have at least 8 characters")
        return token
    token = env.get(TOKEN_ENV, "").strip()
    if token and len(token) < 8:
        raise SettingsError(f"{TOKEN_ENV}: the token must have at least 8 characters")
    return token or None


def _toml_value(value: Any) -> str:
    import tomli_w

    return tomli_w.dumps({"v": value}).partition("=")[2].strip()


def render_toml(settings: ServiceSettings | None = None) -> str:
    """The settings as a commented TOML file (every key with its description); keys whose value
    is None are shown commented out."""
    settings = settings or ServiceSettings()
    lines = ["# shm serve configuration: every key, its default and what it means.", ""]

    def section(model: BaseModel, name: str | None) -> None:
        scalars: list[tuple[str, Any, Any]] = []
        tables: list[tuple[str, Any, Any]] = []
        for key, info in type(model).model_fields.items():
            if key == "structures":
                continue  # arrays of tables, after everything else
            value = getattr(model, key)
            (tables if isinstance(value, BaseModel) else scalars).append((key, info, value))
        if name is not None:
            doc = (type(model).__doc__ or "").strip().splitlines()
            lines.append(f"[{name}]" + (f"  # {doc[0]}" if doc else ""))
        for key, info, value in scalars:
            if info.description:
                lines.append(f"# {info.description}")
            if name == "source" and settings.structures and key in ("spec", "id", "rig"):
                lines.append(f"# {key}: set by each [[structures]] table")
            elif value is None:
                lines.append(f"# {key} = ")
            else:
                if isinstance(value, tuple):
                    value = list(value)
                lines.append(f"{key} = {_toml_value(value)}")
        lines.append("")
        for key, _, value in tables:
            section(value, key if name is None else f"{name}.{key}")

    section(settings, None)
    lines.append(f"# {ServiceSettings.model_fields['structures'].description}; each [[structures]] table has the keys:")
    for key, info in StructureSettings.model_fields.items():
        lines.append(f"#   {key}: {info.description}")
    for structure in settings.structures:
        lines.append("[[structures]]")
        tables = []
        for key in StructureSettings.model_fields:
            value = getattr(structure, key)
            if isinstance(value, dict):
                if value:
                    tables.append((key, value))
            elif value is not None:
                lines.append(f"{key} = {_toml_value(value)}")
        for key, value in tables:
            lines.append(f"[structures.{key}]")
            lines.extend(f"{k} = {_toml_value(list(v) if isinstance(v, tuple) else v)}" for k, v in value.items())
        lines.append("")
    return "\n".join(lines)
