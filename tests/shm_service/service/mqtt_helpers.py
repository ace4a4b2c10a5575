"""Helpers of the tests with a real broker: a simulation as ingest bodies, a publisher."""

from __future__ import annotations

import threading
import time
from urllib.parse import urlsplit

import orjson
import paho.mqtt.client as mqtt
from paho.mqtt.enums import MQTTProtocolVersion

from shm_service.virtual_rig import SimulationSettings, VirtualRig
from shm_service.virtual_rig._record import encode_payloads


def simulated_bodies(duration_s: float, *, seed: int, end_ns: int, body_s: float = 1.0) -> list[bytes]:
    """``duration_s`` of the virtual rig (ambient, 10 s rest; seeded) as ``POST /api/ingest``
    bodies of ``body_s`` each, stamped so that the last sample lies at ``end_ns``."""
    rig = VirtualRig(SimulationSettings(duration=duration_s, rest=10.0, excitation="ambient", seed=seed))
    start = end_ns - int(round(duration_s * 1e9))
    bodies = []
    for block in rig.blocks(body_s):
        messages = []
        for topic, (times, values) in block.measurements.items():
            stamps = (start + (times * 1e9).round()).astype("int64").tolist()
            for t, payload in zip(stamps, encode_payloads(topic, values)):
                messages.append({"topic": topic, "log_time_ns": t, "payload": orjson.loads(payload)})
        bodies.append(orjson.dumps({"messages": messages}))
    return bodies


class Publisher:
    """A field gateway: publishes bodies to the broker with QoS 1 and waits for each PUBACK."""

    def __init__(self, url: str, client_id: str = "gateway") -> None:
        parts = urlsplit(url)
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, protocol=MQTTProtocolVersion.MQTTv5)
        connected = threading.Event()
        self.client.on_connect = lambda *args: connected.set()
        self.client.connect(parts.hostname, parts.port)
        self.client.loop_start()
        if not connected.wait(10):
            raise RuntimeError(f"no connection to {url}")

    def publish(self, topic: str, bodies: list[bytes], timeout_s: float = 60.0) -> None:
        infos = [self.client.publish(topic, body, qos=1) for body in bodies]
        deadline = time.monotonic() + timeout_s
        for info in infos:
            info.wait_for_publish(max(0.1, deadline - time.monotonic()))
            if not info.is_published():
                raise RuntimeError(f"{topic}: a body was not acknowledged by the broker within {timeout_s} s")

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

    def __enter__(self) -> "Publisher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
