"""What an operator's action needs whichever port answers it: the token, and an acknowledgement
that waits a few seconds for the database at most (then 503: retry)."""

from __future__ import annotations

import hmac
from typing import Any

from contract import AlarmDocument

__all__ = ["acknowledge_alarm", "check_token"]


def check_token(configured: str | None, token: str | None) -> None:
    """Raise PermissionError unless ``token`` is the ``configured`` one (none configured: the action is disabled)."""
    if configured is None:
        raise PermissionError("no API token is configured (server.token_file or SHM_TOKEN); this action is disabled")
    # compare_digest: the time taken says nothing about how much of the token was right
    if not token or not hmac.compare_digest(token.encode(), configured.encode()):
        raise PermissionError("missing or wrong token")


def acknowledge_alarm(storage: Any, alarm_id: int, by: str, storage_retry_s: float) -> AlarmDocument:
    """The acknowledged alarm ``alarm_id``; KeyError naming it when there is none."""
    alarm = storage.acknowledge(alarm_id, by, retry_s=min(storage_retry_s, 3.0))
    if alarm is None:
        raise KeyError(f"alarm {alarm_id} does not exist")
    return alarm
