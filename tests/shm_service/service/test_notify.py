"""Notifications: webhook retries with back-off (every attempt logged), e-mail over SMTP
(a local aiosmtpd server)."""

from __future__ import annotations

import time

from svc_helpers import Receiver

from shm_service.service._config import NotifySettings
from shm_service.service._notify import Notifier, notify_targets
from shm_service.service._storage import AlarmChange, Storage, WindowCommit


def _raise(storage):
    change = AlarmChange("raise", "mode2", "frequency", 2, "alarm", 1000.0, 6.0, 5.0, "mode 2 off")
    storage.commit_window(WindowCommit("src", 980.0, 1000.0, [], None, None, [change]))


def test_webhook_retries_with_backoff_and_logs_every_attempt(tmp_path):
    rx = Receiver(fail_first=2)
    try:
        settings = NotifySettings(webhooks=(rx.url,), retry_initial_s=0.05, retry_max_s=0.2)
        st = Storage(tmp_path / "s.sqlite", notify_targets=notify_targets(settings))
        _raise(st)
        n = Notifier(st, settings, environ={})
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not rx.posts:
            n.deliver_due()
            time.sleep(0.02)
        n.stop()
        assert len(rx.posts) == 1 and rx.posts[0]["event"] == "raised" and rx.keys[0] == rx.posts[0]["id"]
        log = st.notification_log()
        assert [r["ok"] for r in log] == [0, 0, 1] and [r["attempt"] for r in log] == [1, 2, 3]
        assert st.outbox()[0]["status"] == "sent"
    finally:
        rx.close()


def test_gives_up_after_max_attempts(tmp_path):
    settings = NotifySettings(webhooks=("http://127.0.0.1:9/none",), retry_initial_s=0.01, retry_max_s=0.01, max_attempts=2,
                              webhook_timeout_s=0.5)
    st = Storage(tmp_path / "s.sqlite", notify_targets=notify_targets(settings))
    _raise(st)
    n = Notifier(st, settings, environ={})
    for _ in range(20):
        n.deliver_due()
        time.sleep(0.02)
    n.stop()
    assert st.outbox()[0]["status"] == "failed" and len(st.notification_log()) == 2


def test_email_over_smtp(tmp_path):
    from aiosmtpd.controller import Controller

    received = []

    class Handler:
        async def handle_DATA(self, server, session, envelope):  # noqa: N802
            received.append(envelope)
            return "250 OK"

    import socket

    with socket.socket() as probe:  # a free loopback port
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    controller = Controller(Handler(), hostname="127.0.0.1", port=port)
    controller.start()
    try:
        settings = NotifySettings(smtp_host="127.0.0.1", smtp_port=port, mail_to=("ops@example.org",))
        st = Storage(tmp_path / "s.sqlite", notify_targets=notify_targets(settings))
        _raise(st)
        n = Notifier(st, settings, environ={})
        n.deliver_due()
        n.stop()
        assert len(received) == 1 and received[0].rcpt_tos == ["ops@example.org"]
        assert b"mode 2 off" in received[0].content
        assert st.outbox()[0]["status"] == "sent"
    finally:
        controller.stop()
