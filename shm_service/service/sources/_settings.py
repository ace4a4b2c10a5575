"""The settings of the sources: ``[sim]`` (the virtual rig as a live source) and ``[source]``
(where the data comes from). ``[source]`` is made of the settings of the stages that judge what a
source delivers, the merge's and the checks', with the source's own keys beside them: the
pipeline takes the section as those stages' settings, so each key has one definition and one
default."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ...recording._plausibility import ValueLimits
from ..stages._checks import CheckSettings
from ..stages._merge import MergeSettings

__all__ = ["MQTT_PASSWORD_ENV", "SOURCE_SPEC", "MqttSettings", "SimSettings", "SourceConfig", "SourceSettings", "check_spec"]


SOURCE_SPEC = "sim | replay:FILE.mcap | follow:FILE.mcap | ingest | mqtt"


def check_spec(value: str) -> str:
    kind, _, arg = value.partition(":")
    if kind in ("sim", "ingest", "mqtt") and not arg:
        return value
    if kind in ("replay", "follow") and arg:
        return value
    raise ValueError(f"source {value!r} must be sim, ingest, mqtt, replay:FILE.mcap or follow:FILE.mcap")


class SimSettings(BaseModel):
    """The virtual rig as a live source (``--source sim``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    duration_s: float = Field(7 * 24 * 3600.0, gt=0, le=7 * 24 * 3600, description="simulated run length, s (the run ends then)")
    seed: int = Field(1, ge=0, description="random seed of the simulation")
    layout: Literal["benchmark", "dense"] = Field("benchmark", description="sensor layout")
    support: Literal["pinned", "clamped"] = Field(
        "pinned", description="pinned: the plain bearing (the beam swings about D); clamped: the fixed bearing (phi = 0)")
    orientation: Literal["hanging", "standing"] = Field(
        "hanging", description="hanging below D, or standing above it as a mast (needs support = clamped; must not buckle)")
    length_m: float = Field(
        4.0, gt=0, le=100, description="beam length, m; the layout's sensors scale with it (damage positions do not)")
    excitation: Literal["paper", "ambient", "decay", "operational"] = Field(
        "ambient", description="excitation of the rig (operational: the support moving randomly and a random distributed load)")
    damage: tuple[str, ...] = Field(("mass:0.126@4.0",), description="damage specs (mass:KG@POS, stiffness:FACTOR@A-B)")
    damage_at_s: float | None = Field(
        900.0, ge=0,
        description="simulated time the damage appears, s (None: never); after rest (60 s), warm-up and the baseline (analytics.baseline_s)")
    temperature_mean_c: float = Field(20.0, description="mean temperature, degC")
    temperature_swing_k: float = Field(40.0, ge=0, description="peak-to-peak temperature swing over the whole run, K")
    block_s: float = Field(1.0, gt=0, le=60, description="simulated seconds per block handed to the pipeline")
    rig: str | None = Field(
        None, description="simulate this rig description (.json/.toml; its beam, support, orientation and sensors, as "
        "shm simulate --rig) instead of the built-in sheet of layout/support/orientation/length_m")
    wind_load_rms: float | None = Field(
        None, ge=0, description="RMS of the wind load along the beam, N/m (None: scaled to the structure for a rig file)")
    storm_start_s: float | None = Field(
        None, ge=0, description="a storm that passes begins, s (None: no storm): the wind load's RMS rises to storm_peak "
        "times its ambient level halfway to storm_end_s and falls back (the virtual rig's WindStorm)")
    storm_end_s: float | None = Field(None, gt=0, description="the storm has passed, s")
    storm_peak: float = Field(3.0, gt=0, le=100, description="the wind load's RMS at the storm's peak over its ambient RMS")
    faults: tuple[str, ...] = Field(
        (), description="sensor faults to inject, KIND:TOPIC[.FIELD]@START+DURATION[:VALUE] with KIND silence, nan, "
        "spike (VALUE added), stuck or clock (stamps shifted by VALUE s); START and DURATION in simulated s, "
        "e.g. spike:/imu/D.accel_y@300+1:100")

    @model_validator(mode="after")
    def _storm(self) -> "SimSettings":
        if (self.storm_start_s is None) != (self.storm_end_s is None):
            raise ValueError("sim.storm_start_s and sim.storm_end_s come together (a storm begins and passes)")
        if self.storm_start_s is not None and self.storm_end_s is not None and not self.storm_start_s < self.storm_end_s:
            raise ValueError(f"sim.storm_start_s={self.storm_start_s} must come before sim.storm_end_s={self.storm_end_s}")
        return self

    @field_validator("faults")
    @classmethod
    def _faults(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        from ._faults import parse_fault

        for spec in value:
            parse_fault(spec)  # raises with the spec's problem
        return value


class SourceSettings(MergeSettings, CheckSettings):
    """Where the data comes from.

    With how its sensors are waited for (``lateness_s``, the merge's settings) and judged
    (``silent_after_s``, ``stuck_after_s``, the checks' settings): the pipeline takes this section as
    those stages' settings."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    spec: str = Field("sim", description="sim | replay:FILE.mcap | follow:FILE.mcap | ingest | mqtt")
    id: str | None = Field(None, description="source id of the trend rows (default: sim, ingest, or the recording's file stem)")
    speed: float | Literal["max"] = Field(1.0, description="sim/replay pace: a factor of real time, or max")
    keep_running: bool = Field(False, description="keep serving the API after a replay (or sim run) ends")
    rig: str | None = Field(None, description="rig description (.json/.toml) for ingest and mqtt, or to replace a recording's rig.json")
    layout: Literal["benchmark", "dense"] = Field("benchmark", description="rig layout for ingest and mqtt when no rig file is given")
    follow_poll_s: float = Field(0.2, gt=0, description="how often a followed file is checked for new data, s")
    follow_idle_s: float | None = Field(None, gt=0, description="stop following after this long without growth, s (None: never)")
    follow_rotations: bool = Field(
        True, description="follow: after the writer closed the file, keep watching its name for a new file (a logger's "
        "rotation; a replaced file is read from its start); false: the source ends with the file")
    time_window_s: float = Field(
        3600.0, gt=0, description="a stamp more than this before the source's newest one, or after its current time, is "
        "rejected (implausible_time), s; ingest's current time runs on with the wall clock, sim and replay have their own")
    max_ahead_s: float | None = Field(
        None, gt=0, description="a sensor whose stamps run ahead of every other sensor of the source by more than this is "
        "rejected (ahead_of_source: its clock jumped), s (None: lateness_s)")
    future_tolerance_s: float = Field(
        60.0, gt=0, description="ingest: no stamp may lie beyond the wall clock plus this, s; a stamp this close to the "
        "wall clock is always on time")
    limits: ValueLimits = Field(ValueLimits(), description="readings beyond these are rejected (implausible_value)")

    @field_validator("speed", mode="before")
    @classmethod
    def _speed(cls, value: Any) -> Any:
        if isinstance(value, str) and value != "max":
            try:
                value = float(value)
            except ValueError:
                raise ValueError(f"speed {value!r} must be a number > 0 or 'max'") from None
        if isinstance(value, (int, float)) and not (value > 0 and value < 1e6):
            raise ValueError(f"speed {value!r} must be > 0 (or 'max')")
        return value

    @field_validator("spec")
    @classmethod
    def _spec(cls, value: str) -> str:
        return check_spec(value)

    @property
    def kind(self) -> str:
        return self.spec.partition(":")[0]

    @property
    def path(self) -> str | None:
        return self.spec.partition(":")[2] or None



MQTT_PASSWORD_ENV = "SHM_MQTT_PASSWORD"


class MqttSettings(BaseModel):
    """The MQTT broker that structures with ``source = "mqtt"`` take their data from: each
    subscribes ``TOPIC_PREFIX/ID/ingest`` with QoS 1 in a persistent session of its own (client id
    ``shm-TOPIC_PREFIX-ID``), each message's body a ``POST /api/ingest`` body. The password comes
    from ``password_file`` or the environment variable SHM_MQTT_PASSWORD, never from this file."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    url: str | None = Field(None, description="the broker, mqtt://HOST[:PORT] (default port 1883) or mqtts://HOST[:PORT] "
                            "(TLS, default port 8883); needed when a structure's source is mqtt")
    topic_prefix: str = Field("shm", min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_-]+(/[A-Za-z0-9_-]+)*$",
                              description="a structure ID's bodies are published to TOPIC_PREFIX/ID/ingest")
    username: str | None = Field(None, description="user name at the broker (None: anonymous)")
    password_file: str | None = Field(None, description="file holding the broker password (first line); else the "
                                      "environment variable SHM_MQTT_PASSWORD")
    ca_file: str | None = Field(None, description="mqtts: CA certificates (PEM) the broker's certificate is checked "
                                "against (default: the system's)")
    cert_file: str | None = Field(None, description="mqtts: this client's certificate (PEM), for brokers that require one")
    key_file: str | None = Field(None, description="mqtts: the private key (PEM) of cert_file")
    tls_insecure: bool = Field(False, description="mqtts: accept a broker certificate whose host name does not match "
                               "(the chain is still checked; for a broker reached by an address its certificate lacks)")
    keepalive_s: int = Field(30, ge=5, le=3600, description="MQTT keep-alive, s: a dead connection is noticed within "
                             "1.5 times this")
    session_expiry_s: int = Field(
        7 * 86400, ge=60, le=2**32 - 2, description="how long the broker keeps a structure's session, and the messages "
        "published to it, while no node holds the structure, s")
    receive_maximum: int = Field(
        2000, ge=2, le=65535, description="bodies the broker sends a structure before it has acknowledged the first; "
        "a body is acknowledged once the window after it is committed, so half of this must hold the bodies of the "
        "calibration, warm-up and two windows (2000: 1 s bodies)")
    reconnect_max_s: float = Field(30.0, ge=1, le=3600, description="longest wait between attempts to reach the broker, s "
                                   "(from 1 s, doubling)")

    @field_validator("url")
    @classmethod
    def _url(cls, value: str | None) -> str | None:
        if value is None:
            return None
        from urllib.parse import urlsplit

        parts = urlsplit(value)
        if parts.scheme not in ("mqtt", "mqtts"):
            raise ValueError(f"url {value!r} must be mqtt://HOST[:PORT] or mqtts://HOST[:PORT]")
        try:
            port = parts.port
        except ValueError:
            raise ValueError(f"url {value!r}: the port must be a number within 1-65535") from None
        if not parts.hostname:
            raise ValueError(f"url {value!r} has no host")
        if port == 0 or parts.path not in ("", "/") or parts.query or parts.fragment:
            raise ValueError(f"url {value!r} must be mqtt://HOST[:PORT] or mqtts://HOST[:PORT], nothing after the port "
                             "(the topics come from topic_prefix)")
        if parts.username or parts.password:
            raise ValueError(f"url {value!r}: give the user as mqtt.username and the password in mqtt.password_file "
                             "or SHM_MQTT_PASSWORD, not in the URL")
        return value

    @field_validator("password_file", "ca_file", "cert_file", "key_file")
    @classmethod
    def _file(cls, value: str | None) -> str | None:
        if value is not None and not Path(value).is_file():
            raise ValueError(f"{value} does not exist (or is not a file)")
        return value

    @model_validator(mode="after")
    def _tls(self) -> "MqttSettings":
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("mqtt.cert_file and mqtt.key_file come together (a client certificate and its key)")
        tls_keys = [k for k in ("ca_file", "cert_file", "tls_insecure") if k in self.model_fields_set]
        if tls_keys and self.url is not None and not self.url.startswith("mqtts:"):
            raise ValueError(f"mqtt.{tls_keys[0]} needs TLS: an mqtts:// url")
        return self

    @property
    def tls(self) -> bool:
        return self.url is not None and self.url.startswith("mqtts:")

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) of ``url``."""
        from urllib.parse import urlsplit

        parts = urlsplit(self.url or "")
        return parts.hostname or "", parts.port or (8883 if self.tls else 1883)

    def password(self, environ: Mapping[str, str] | None = None) -> str | None:
        """The password: the first line of ``password_file``, else SHM_MQTT_PASSWORD (None: neither)."""
        if self.password_file is not None:
            try:
                text = Path(self.password_file).read_text(encoding="utf-8")
            except OSError as exc:
                raise ValueError(f"mqtt.password_file: cannot read {self.password_file}: {exc}") from None
            return text.splitlines()[0].strip() if text.strip() else ""
        env = os.environ if environ is None else environ
        return env.get(MQTT_PASSWORD_ENV) or None


class SourceConfig(Protocol):
    """What a source reads of the service's settings: the sections ``[source]`` and ``[sim]``."""

    @property
    def source(self) -> SourceSettings: ...

    @property
    def sim(self) -> SimSettings: ...
