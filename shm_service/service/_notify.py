"""Delivery of alarm notifications from the outbox: webhooks (JSON POST) and e-mail (SMTP).

The outbox rows are written in the same transaction as the alarm event that causes them, so a
crash never loses one. A row is marked sent in the transaction that logs the successful attempt.
Delivery is therefore at-least-once: only a crash in the instant between the receiver's answer
and that commit could repeat a notification, and every notification carries a stable id (body
``id`` and the ``Idempotency-Key`` header) by which a receiver recognises a repeat. Failed
attempts are retried with exponential back-off; every attempt is logged.
"""

from __future__ import annotations

import json
import logging
import os
import smtplib
import threading
import time
from email.message import EmailMessage
from typing import Any

import httpx

from ._config import NotifySettings
from ._sinks import SinkGuard
from ._storage import Storage

__all__ = ["Notifier", "notify_targets"]

log = logging.getLogger("shm.serve.notify")


def notify_targets(settings: NotifySettings) -> list[tuple[str, str]]:
    targets = [("webhook", url) for url in settings.webhooks]
    if settings.smtp_host and settings.mail_to:
        targets.append(("email", ",".join(settings.mail_to)))
    return targets


class Notifier:
    def __init__(self, storage: Storage, settings: NotifySettings, environ: dict[str, str] | None = None) -> None:
        self.storage = storage
        self.settings = settings
        self.environ = dict(os.environ if environ is None else environ)
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self.sent = 0
        self.failed_attempts = 0
        # Failed deliveries by channel and errors of the loop itself: counted, logged once per kind.
        self.guard = SinkGuard("notifier", log)
        self._client = httpx.Client(timeout=settings.webhook_timeout_s, follow_redirects=False)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, name="notifier", daemon=True)
        self._thread.start()

    def wake(self) -> None:
        self._wake.set()

    def stop(self, drain_s: float = 0.0) -> None:
        deadline = time.monotonic() + drain_s
        while drain_s and time.monotonic() < deadline and self.storage.due_notifications(time.time(), 1):
            time.sleep(0.05)
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(10.0)
        self._client.close()

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.deliver_due()
            except Exception as exc:  # never let the notifier die
                self.guard.record("loop", exc)
            self._wake.wait(0.2)
            self._wake.clear()

    def deliver_due(self) -> int:
        done = 0
        for row in self.storage.due_notifications(time.time()):
            if self._stop.is_set():
                break
            ok, detail = self._send(row)
            attempt = int(row["attempts"]) + 1
            delay = min(self.settings.retry_initial_s * 2 ** (attempt - 1), self.settings.retry_max_s)
            give_up = not ok and attempt >= self.settings.max_attempts
            self.storage.record_attempt(row["id"], ok, detail, next_attempt_at=time.time() + delay, give_up=give_up)
            if ok:
                self.sent += 1
                done += 1
            else:
                self.failed_attempts += 1
                self.guard.record(str(row["channel"]), f"notification {row['id']} to {row['target']} (attempt {attempt}): {detail}")
        return done

    def _send(self, row: dict[str, Any]) -> tuple[bool, str]:
        try:
            payload = json.loads(row["payload"])
            if row["channel"] == "webhook":
                r = self._client.post(row["target"], content=row["payload"].encode(),
                                      headers={"Content-Type": "application/json", "Idempotency-Key": payload["id"]})
                return (200 <= r.status_code < 300), f"HTTP {r.status_code}"
            if row["channel"] == "email":
                return self._mail(row["target"].split(","), payload)
            return False, f"unknown channel {row['channel']!r}"
        except (httpx.HTTPError, OSError, smtplib.SMTPException, ValueError, KeyError) as exc:
            # A bad stored row (malformed payload) fails this row's attempt, not the others'.
            return False, f"{type(exc).__name__}: {exc}"

    def _mail(self, to: list[str], payload: dict[str, Any]) -> tuple[bool, str]:
        s = self.settings
        alarm = payload["alarm"]
        msg = EmailMessage()
        msg["Subject"] = f"[shm] {payload['level']} {payload['event']}: {alarm['message']}"
        msg["From"] = s.mail_from
        msg["To"] = ", ".join(to)
        msg["Message-ID"] = f"<{payload['id']}@shm>"
        msg.set_content(json.dumps(payload, indent=2))
        with smtplib.SMTP(s.smtp_host, s.smtp_port, timeout=s.webhook_timeout_s) as smtp:
            if s.smtp_starttls:
                smtp.starttls()
            if s.smtp_user:
                smtp.login(s.smtp_user, self.environ.get("SHM_SMTP_PASSWORD", ""))
            smtp.send_message(msg)
        return True, "SMTP accepted"
