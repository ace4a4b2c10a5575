"""An MQTT source: one structure's bodies from the broker (``source = "mqtt"``).

The structure subscribes ``TOPIC_PREFIX/ID/ingest`` with QoS 1 in a persistent session of its own
(MQTT 5, client id ``shm-TOPIC_PREFIX-ID``, no clean start, ``mqtt.session_expiry_s``): while no
node holds the structure the broker keeps what is published for it, and hands it over to the next
session of that client id. Each message is one ``POST /api/ingest`` body, validated and counted by
the ingest's ``IngestValidator``. A message is acknowledged (paho's manual acknowledgement, in
the order received) only once the structure no longer needs it after a restart: once the windows
committed to the database reach far enough that a structure resumed from them (which analyses from
the window after the last one, once its filter has converged) begins its data after the message's
last sample (``committed_until_s``, the structure's). A node that dies leaves every message it has not committed to the
broker, which sends them to the next holder of the session: nothing is lost, and the windows
committed already are not analysed again (the pipeline resumes after the last one). Without that
hook (or while more than ``mqtt.receive_maximum`` / 2 wait) a message is acknowledged once its
batch is in the pipeline's queue.

One thread per structure runs the connection and the hand-off. It never blocks on the queue: a
body waits while the queue is full, and the broker sends no more than ``mqtt.receive_maximum``
unacknowledged bodies, so back-pressure reaches the broker and the connection stays alive
meanwhile.
"""

from __future__ import annotations

import logging
import queue
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from contract import RigDescription

from ...recording._plausibility import SourceClock, ValueLimits
from ._settings import MqttSettings
from ..stages._pipeline import Batch
from ._ingest import IngestError, IngestResult, IngestValidator, parse_body
from ._sources import Source

__all__ = ["MqttSource", "client_id", "ingest_topic"]

log = logging.getLogger("shm.serve.mqtt")

_IDLE_S = 0.25  # the network loop's wait when nothing is pending (a stop is noticed within it)
_FULL_S = 0.05  # ... while a body waits for room in the queue


def ingest_topic(settings: MqttSettings, structure_id: str) -> str:
    """The topic the structure's bodies are published to: ``TOPIC_PREFIX/ID/ingest``."""
    return f"{settings.topic_prefix}/{structure_id}/ingest"


def client_id(settings: MqttSettings, structure_id: str) -> str:
    """The structure's fixed client id (its session at the broker): ``shm-TOPIC_PREFIX-ID``."""
    return f"shm-{settings.topic_prefix.replace('/', '-')}-{structure_id}"


@dataclass
class _Body:
    """A message received and not yet acknowledged."""

    connection: int  # the connection it came on (its mid means nothing on another)
    mid: int
    qos: int
    payload: bytes
    dup: bool  # the broker sent it before (not acknowledged then)
    result: IngestResult | None = None  # validated, waiting for room in the queue
    refused: str | None = None  # not an ingest body: why


class MqttSource(Source):
    """``source = "mqtt"``: the structure's bodies from the broker, as ``POST /api/ingest`` takes them."""

    kind = "mqtt"

    def __init__(self, source_id: str, out: queue.Queue, rig: RigDescription, settings: MqttSettings, *,
                 max_messages: int, raw: bool, clock: SourceClock | None = None, limits: ValueLimits | None = None,
                 password: str | None = None) -> None:
        super().__init__(source_id, out)
        if settings.url is None:
            raise ValueError("mqtt.url must be set for a source = \"mqtt\"")
        self.rig = rig
        self.settings = settings
        self.validator = IngestValidator(rig, max_messages=max_messages, clock=clock, limits=limits)
        self.raw = raw
        self.topic = ingest_topic(settings, source_id)
        self.client_id = client_id(settings, source_id)
        self._password = password
        self._pending: deque[_Body] = deque()
        self._connection = 0  # counts the connections accepted by the broker
        self._linked = False  # a socket to the broker (CONNECT sent)
        self.connected = False  # the broker accepted it (CONNACK) and it subscribed
        self.session_present: bool | None = None
        self.link_error: str | None = None
        self._refusal: str | None = None
        self.down_since: float | None = time.time()
        self.bodies = 0
        self.refused_bodies = 0
        self.redelivered = 0
        self._delay = 1.0
        self._client: Any = None
        # handed on, acknowledged once committed: (connection, mid, qos, newest sample s or None)
        self._handed: deque[tuple[int, int, int, float | None]] = deque()
        #: data time (UNIX s) before which a structure resumed from its committed state needs no
        #: sample again (None: nothing committed yet); unset: acknowledged once in the queue
        self.committed_until_s: Callable[[], float | None] | None = None
        self.acked_early = 0

    # -- lifecycle ----------------------------------------------------------------------------

    def start_on(self, scheduler: Any) -> None:
        """A thread of its own (the connection's network loop), not the scheduler's pool."""
        self.start()

    def run(self) -> None:
        self.state = "running"
        client = self._make_client()
        try:
            while not self._stop.is_set():
                if not self._linked and not self._link(client):
                    self._stop.wait(self._delay)
                    self._delay = min(2 * self._delay, self.settings.reconnect_max_s)
                    continue
                rc = client.loop(timeout=_FULL_S if self._pending else _IDLE_S)
                if rc != 0:
                    from paho.mqtt.client import error_string

                    if self._linked:
                        self._lost(f"connection lost: {error_string(rc)}")
                    continue
                self._hand_on(client)
                self._acknowledge(client)
        finally:
            if self._linked:
                client.disconnect()  # the session stays (its expiry is the CONNECT's)
                client.loop(timeout=0.1)
            self._linked = self.connected = False
        if self.state == "running":
            self.state = "stopped"

    def _make_client(self) -> Any:
        from paho.mqtt.client import Client
        from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion
        from paho.mqtt.packettypes import PacketTypes
        from paho.mqtt.properties import Properties

        s = self.settings
        client = Client(CallbackAPIVersion.VERSION2, client_id=self.client_id, protocol=MQTTProtocolVersion.MQTTv5,
                        manual_ack=True, reconnect_on_failure=False)
        if s.username is not None:
            client.username_pw_set(s.username, self._password)
        if s.tls:
            import ssl

            client.tls_set(ca_certs=s.ca_file, certfile=s.cert_file, keyfile=s.key_file, cert_reqs=ssl.CERT_REQUIRED)
            client.tls_insecure_set(s.tls_insecure)
        client.on_connect = self._on_connect
        client.on_message = self._on_message
        client.on_disconnect = self._on_disconnect
        properties = Properties(PacketTypes.CONNECT)
        properties.SessionExpiryInterval = s.session_expiry_s
        properties.ReceiveMaximum = s.receive_maximum
        host, port = s.address
        # connect_async only stores where and how; every attempt is a reconnect() on this thread
        client.connect_async(host, port, keepalive=s.keepalive_s, clean_start=False, properties=properties)
        self._client = client
        return client

    def _link(self, client: Any) -> bool:
        try:
            client.reconnect()
        except OSError as exc:  # refused, unreachable, TLS handshake (ssl.SSLError is one)
            self._note_down(f"cannot reach the broker {self.settings.url}: {type(exc).__name__}: {exc}")
            return False
        self._linked = True
        return True

    def _lost(self, why: str) -> None:
        self._linked = self.connected = False
        self._note_down(self._refusal or why)  # a refusal says more than the closed socket after it
        self._refusal = None

    def _note_down(self, why: str) -> None:
        if self.link_error != why:
            log.warning("structure %s: mqtt: %s; retrying", self.id, why)
        self.link_error = why
        if self.down_since is None:
            self.down_since = time.time()

    # -- paho's callbacks (on this thread, inside client.loop) ------------------------------

    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if reason.is_failure:
            self._refusal = f"the broker {self.settings.url} refused the connection: {reason}"
            self._note_down(self._refusal)
            self._delay = self.settings.reconnect_max_s  # a refusal (credentials) does not mend by hammering
            return
        from paho.mqtt.subscribeoptions import SubscribeOptions

        self._connection += 1
        self.session_present = bool(flags.session_present)
        # The broker sends every unacknowledged body again when it kept the session (those handed on
        # already come back as duplicates, acknowledged then); when it did not, there is nothing to
        # acknowledge them to. Either way the earlier connection's are done with here.
        self._handed.clear()
        if self.session_present:
            self._pending.clear()
        client.subscribe(self.topic, options=SubscribeOptions(qos=1, retainHandling=SubscribeOptions.RETAIN_DO_NOT_SEND))
        self.connected = True
        self.link_error = self.down_since = None
        self._delay = 1.0
        log.info("structure %s: mqtt: connected to %s as %s (session %s), subscribed %s", self.id, self.settings.url,
                 self.client_id, "resumed" if self.session_present else "new", self.topic)

    def _on_disconnect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if self._linked and not self._stop.is_set():
            self._lost(f"the connection ended: {reason}")

    def _on_message(self, client: Any, userdata: Any, message: Any) -> None:
        self._pending.append(_Body(self._connection, message.mid, message.qos, bytes(message.payload), bool(message.dup)))

    # -- the hand-off ---------------------------------------------------------------------------

    def _hand_on(self, client: Any) -> None:
        """The waiting bodies, in order, into the pipeline's queue while it has room; each
        acknowledged once its batch is in the queue (or it held nothing to hand on)."""
        while self._pending:
            body = self._pending[0]
            if body.result is None and body.refused is None:
                try:
                    body.result = self.validator.validate(parse_body(body.payload))
                except IngestError as exc:
                    body.refused = str(exc)
            result = body.result
            if body.refused is not None or result is None:
                self.refused_bodies += 1
                self.rejected["malformed_body"] += 1
                self.problems = [*self.problems, f"mqtt: a body on {self.topic} was refused: {body.refused}"][-20:]
            elif body.dup and not result.accepted and set(result.rejected) == {"duplicate"}:
                self.redelivered += 1  # taken before its acknowledgement reached the broker
            else:
                if result.blocks or result.refused_by_topic:
                    batch = Batch(result.blocks, result.raw if self.raw else None, refused=dict(result.refused_by_topic))
                    try:
                        self.out.put_nowait(batch)
                    except queue.Full:
                        return  # it waits, unacknowledged; the broker holds back the rest
                # only now, with the batch handed on, do the topics' last times move
                self.validator.commit(result)
                self._count(result.blocks)
                self.rejected.update(result.rejected)
                self.bodies += 1
            self._pending.popleft()
            if body.connection == self._connection and self.connected:
                newest = None if result is None or not result.blocks else max(int(b.log_time_ns[-1]) for b in result.blocks) / 1e9
                self._handed.append((body.connection, body.mid, body.qos, newest))
            # else: a body of an earlier connection whose session the broker had lost: nothing to acknowledge

    def _acknowledge(self, client: Any) -> None:
        """Acknowledge, in order, the handed-on bodies the structure no longer needs (see the module)."""
        until = None if self.committed_until_s is None else self.committed_until_s()
        most = max(1, self.settings.receive_maximum // 2)
        while self._handed:
            connection, mid, qos, newest = self._handed[0]
            if self.committed_until_s is not None and newest is not None and (until is None or newest >= until):
                if len(self._handed) <= most:
                    return
                # so many wait for a window that the broker would stop sending: the oldest goes now
                if self.acked_early == 0:
                    log.warning("structure %s: mqtt: %d bodies wait for their window to be committed (more than "
                                "mqtt.receive_maximum / 2): acknowledged once in the queue from now on (a crash may "
                                "lose what is not committed); raise mqtt.receive_maximum", self.id, len(self._handed))
                self.acked_early += 1
            self._handed.popleft()
            if connection == self._connection and self.connected:
                client.ack(mid, qos)

    # -- what it says about itself ------------------------------------------------------------

    def health_problems(self) -> list[str]:
        problems = list(self.validator.clock.problems())
        if not self.connected and self.state == "running":
            since = "" if self.down_since is None else time.strftime(" since %H:%M:%S UTC", time.gmtime(self.down_since))
            problems.append(f"mqtt: not connected to the broker{since}: {self.link_error or f'connecting to {self.settings.url}'}; what is "
                            f"published to {self.topic} meanwhile waits in the session {self.client_id} at the broker")
        return problems

    def status(self) -> dict[str, Any]:
        broker = {"url": self.settings.url, "topic": self.topic, "client_id": self.client_id, "connected": self.connected,
                  "session_present": self.session_present, "connects": self._connection, "bodies": self.bodies,
                  "refused_bodies": self.refused_bodies, "redelivered": self.redelivered,
                  "unacknowledged": len(self._handed), "acked_early": self.acked_early,
                  "error": None if self.connected else self.link_error}
        return {**super().status(), "clock_jumps": self.validator.clock.jump_count, "broker": broker}
