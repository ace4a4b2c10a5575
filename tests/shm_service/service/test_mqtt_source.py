"""Structures that take their data from a real MQTT broker (Mosquitto, ``source = "mqtt"``): the
bodies become the windows the HTTP ingest makes of them; what is published while no node holds
the structure is kept in its persistent session and delivered when it comes back; a malformed
body is counted, the valid ones around it are kept; an unreachable broker shows in the health,
and the source connects once the broker is there."""

from __future__ import annotations

import sqlite3
import time

import orjson
import pytest
from mqtt_helpers import Publisher, simulated_bodies
from svc_helpers import fast_overrides, wait_for

from shm_service.service import MonitoringService, SettingsError, load_settings

def _fleet(tmp_path, structures, **extra):
    return load_settings(None, {**fast_overrides(tmp_path, **{"archive.enabled": False, **extra}), "structures": structures})


def _messages(bodies) -> int:
    return sum(len(orjson.loads(b)["messages"]) for b in bodies)


def _connected(service, sid):
    return wait_for(lambda: service.structure(sid).source.connected or None, 30, f"{sid} to connect to the broker")


def _trends(db, source):
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT window_start_s, mode, frequency_hz FROM trends WHERE source = ? "
                           "ORDER BY window_start_s, mode", (source,)).fetchall()
    finally:
        con.close()


# -- configuration --------------------------------------------------------------------------------


@pytest.mark.parametrize("mqtt, words", [
    ({}, ["mqtt.url must be set", "['b']"]),
    ({"url": "http://127.0.0.1:1883"}, ["mqtt.url", "mqtt://HOST"]),
    ({"url": "mqtt://127.0.0.1:99999"}, ["mqtt.url", "port"]),
    ({"url": "mqtt://127.0.0.1:1883/topic"}, ["mqtt.url", "topic_prefix"]),
    ({"url": "mqtt://user:secret@127.0.0.1"}, ["mqtt.url", "password_file"]),
    ({"url": "mqtt://127.0.0.1", "topic_prefix": "a/+"}, ["mqtt.topic_prefix"]),
    ({"url": "mqtts://127.0.0.1", "ca_file": "/no/such/ca.pem"}, ["mqtt.ca_file", "/no/such/ca.pem"]),
    ({"url": "mqtt://127.0.0.1", "tls_insecure": True}, ["mqtt.tls_insecure", "mqtts://"]),
    ({"url": "mqtt://127.0.0.1", "receive_maximum": 0}, ["mqtt.receive_maximum"]),
])
def test_bad_mqtt_settings_are_refused_naming_the_key(tmp_path, mqtt, words):
    with pytest.raises(SettingsError) as info:
        _fleet(tmp_path, [{"id": "a"}, {"id": "b", "source": "mqtt"}], mqtt=mqtt)
    for word in words:
        assert word in str(info.value)


def test_a_client_certificate_needs_its_key(tmp_path):
    cert = tmp_path / "client.pem"
    cert.write_text("-----BEGIN CERTIFICATE-----\n")
    with pytest.raises(SettingsError, match="mqtt.cert_file and mqtt.key_file come together"):
        _fleet(tmp_path, [{"id": "b", "source": "mqtt"}], mqtt={"url": "mqtts://127.0.0.1", "cert_file": str(cert)})


def test_mqtt_settings_and_the_topic_and_session_of_a_structure(tmp_path):
    from shm_service.service.sources._mqtt import client_id, ingest_topic

    settings = _fleet(tmp_path, [{"id": "mast-7", "source": "mqtt"}], mqtt={"url": "mqtts://broker.plant", "topic_prefix": "site/a"})
    m = settings.for_structure(settings.structures[0]).mqtt
    assert (m.url, m.tls, m.address) == ("mqtts://broker.plant", True, ("broker.plant", 8883))
    assert ingest_topic(m, "mast-7") == "site/a/mast-7/ingest" and client_id(m, "mast-7") == "shm-site-a-mast-7"
    assert load_settings(None, {"mqtt": {"url": "mqtt://10.0.0.5"}}).mqtt.address == ("10.0.0.5", 1883)
    # the default service has no broker and needs none
    assert load_settings(None, {}).mqtt.url is None


# -- with the broker ------------------------------------------------------------------------------


@pytest.mark.e2e
def test_bodies_from_the_broker_make_the_windows_the_http_ingest_makes(tmp_path, mqtt_server):
    """The same bodies into an ``ingest`` structure by HTTP and into an ``mqtt`` one by the broker,
    while the service runs: the same samples taken and the same trend rows committed."""
    settings = _fleet(tmp_path, [{"id": "http", "source": "ingest"}, {"id": "broker", "source": "mqtt"}],
                      mqtt={"url": mqtt_server.url, "topic_prefix": "same"}, workers=1)
    bodies = simulated_bodies(100.0, seed=4, end_ns=time.time_ns())
    total = _messages(bodies)
    service = MonitoringService(settings, environ={})
    service.start()
    try:
        _connected(service, "broker")
        with Publisher(mqtt_server.url) as gateway:
            gateway.publish("same/broker/ingest", bodies)
        for body in bodies:
            while service.ingest(orjson.loads(body), "http") is None:
                time.sleep(0.1)  # the pipeline was full: nothing taken, sent again
        for sid in ("http", "broker"):
            wait_for(lambda: sum(service.structure(sid).pipeline.samples.values()) == total or None, 120,  # noqa: B023
                     f"{sid}'s samples")
        broker = service.structure("broker").source
        st = broker.status()
        assert st["messages"] == total and st["rejected"] == 0
        assert st["broker"]["bodies"] == len(bodies) and st["broker"]["connected"] and st["broker"]["redelivered"] == 0
        assert service.health().status == "ok", service.health()
    finally:
        service.stop(drain_s=120)
    db = settings.db
    rows = _trends(db, "broker")
    assert len(rows) > 0
    assert rows == _trends(db, "http")


@pytest.mark.e2e
def test_what_is_published_while_no_node_holds_the_structure_waits_in_its_session(tmp_path, mqtt_server):
    """A first run opens the structure's session and stops; bodies published meanwhile, one of them
    not JSON and one with a malformed message among valid ones, are delivered to the next run:
    every valid message taken, the bad ones counted as HTTP ingest counts them."""
    settings = _fleet(tmp_path, [{"id": "m1", "source": "mqtt"}], mqtt={"url": mqtt_server.url, "topic_prefix": "kept"},
                      workers=1)
    first = MonitoringService(settings, environ={})
    first.start()
    try:
        _connected(first, "m1")
        assert first.structure("m1").source.status()["broker"]["session_present"] is False
    finally:
        first.stop(drain_s=0)

    bodies = simulated_bodies(12.0, seed=5, end_ns=time.time_ns())
    mixed = orjson.loads(bodies[5])
    mixed["messages"].insert(3, {"topic": "/imu/D", "log_time_ns": "soon", "payload": {}})  # malformed
    mixed["messages"].insert(7, {"topic": "/imu/nowhere", "log_time_ns": 1, "payload": {}})  # unknown_topic
    sent = [*bodies[:5], b"{not json", orjson.dumps(mixed), *bodies[6:]]
    with Publisher(mqtt_server.url) as gateway:
        gateway.publish("kept/m1/ingest", sent)

    second = MonitoringService(settings, environ={})
    second.start()
    try:
        src = second.structure("m1").source
        total = _messages(bodies)
        wait_for(lambda: src.messages == total or None, 60, "the kept bodies")
        st = src.status()
        assert st["broker"]["session_present"] is True
        assert st["broker"]["bodies"] == len(bodies) and st["broker"]["refused_bodies"] == 1
        assert st["rejected_by_reason"] == {"malformed_body": 1, "malformed": 1, "unknown_topic": 1}
        assert st["rejected"] == 3
        assert any("body on kept/m1/ingest was refused" in p for p in st["problems"])
        wait_for(lambda: sum(second.structure("m1").pipeline.samples.values()) == total or None, 60, "the samples")
    finally:
        second.stop(drain_s=0)


@pytest.mark.e2e
def test_an_unreachable_broker_shows_in_the_health_and_is_reached_once_it_is_there(tmp_path):
    from shm_service.devservers import free_port, start_mosquitto

    port = free_port()
    settings = _fleet(tmp_path, [{"id": "far", "source": "mqtt"}],
                      mqtt={"url": f"mqtt://127.0.0.1:{port}", "reconnect_max_s": 1.0}, workers=1)
    service = MonitoringService(settings, environ={})
    service.start()
    server = None
    try:
        health = wait_for(lambda: (lambda h: h if h.reasons else None)(service.health()), 30, "the broker's absence")
        assert health.status == "degraded"
        assert any(r.startswith("far: mqtt: not connected to the broker") and f"127.0.0.1:{port}" in r
                   for r in health.reasons), health
        summary = service.structure("far").summary()
        assert summary.state == "degraded" and "not connected" in (summary.error or "")
        assert service.structure("far").source.status()["broker"]["connected"] is False
        server = start_mosquitto(port=port)
        _connected(service, "far")
        bodies = simulated_bodies(3.0, seed=6, end_ns=time.time_ns())
        with Publisher(server.url) as gateway:
            gateway.publish("shm/far/ingest", bodies)
        src = service.structure("far").source
        wait_for(lambda: src.messages == _messages(bodies) or None, 30, "the bodies")
        # (the sensors fall silent after these 3 s, which the health may say by now: the broker it does not)
        assert not any("mqtt" in r for r in service.health().reasons)
    finally:
        service.stop(drain_s=0)
        if server is not None:
            server.stop()


@pytest.mark.e2e
def test_a_structure_stopped_mid_stream_resumes_from_its_committed_windows_none_missing_none_doubled(tmp_path, mqtt_server):
    """The bodies of a structure are acknowledged only once the window after them is committed: a
    run that stops mid-stream leaves the rest in its session, and the next run, resumed from the
    committed state, commits exactly the windows one run of all the data commits (the HTTP
    ingest of the same bodies, beside it)."""
    settings = _fleet(tmp_path, [{"id": "whole", "source": "ingest"}, {"id": "cut", "source": "mqtt"}],
                      mqtt={"url": mqtt_server.url, "topic_prefix": "resume"}, workers=1)
    bodies = simulated_bodies(110.0, seed=8, end_ns=time.time_ns())
    last_ns = max(m["log_time_ns"] for m in orjson.loads(bodies[-1])["messages"])
    first = MonitoringService(settings, environ={})
    first.start()
    try:
        _connected(first, "cut")
        with Publisher(mqtt_server.url) as gateway:
            gateway.publish("resume/cut/ingest", bodies[:70])
        for body in bodies:
            while first.ingest(orjson.loads(body), "whole") is None:
                time.sleep(0.1)
        cut = first.structure("cut")
        wait_for(lambda: cut.pipeline.windows_committed >= 2 or None, 120, "windows of the first run")
        wait_for(lambda: cut.source.status()["messages"] == _messages(bodies[:70]) or None, 60, "the first 70 bodies")
        held = cut.source.status()["broker"]["unacknowledged"]
        assert held > 0  # what the committed windows do not cover yet stays with the broker
    finally:
        first.stop(drain_s=120)
    committed = len(_trends(settings.db, "cut"))
    with Publisher(mqtt_server.url) as gateway:  # while no one holds the structure
        gateway.publish("resume/cut/ingest", bodies[70:])
    second = MonitoringService(settings, environ={})
    second.start()
    try:
        cut = second.structure("cut")
        wait_for(lambda: cut.pipeline.newest_ns == last_ns or None, 120, "the rest of the data")
        assert cut.pipeline.resumed and cut.source.status()["broker"]["session_present"] is True
    finally:
        second.stop(drain_s=120)
    rows = _trends(settings.db, "cut")
    whole = _trends(settings.db, "whole")
    assert committed < len(rows)
    starts = [(r[0], r[1]) for r in rows]
    assert len(set(starts)) == len(starts)  # none twice
    assert starts == [(r[0], r[1]) for r in whole]  # none missing
