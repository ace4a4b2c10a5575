"""What the API serves while ``shm serve`` cannot build its service yet: a ``follow:`` source
whose file (and its ``rig.json``, which the model needs) is not there yet. The API is up and
authenticated as usual; ``/healthz`` answers "degraded" with the reason, every other route 503
with ``Retry-After`` (``ServiceStarting``), until the service replaces this stand-in in the
``ServiceSlot`` the app was built on.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any, Generic, Protocol

from contract import HealthDocument, ServicePort, ServiceStarting

from .._config import ServiceSettings, resolve_token
from ._operator import check_token

__all__ = ["ServiceSlot", "ServiceStarting", "StartingService", "port_methods"]


class StartingService:
    """The API's service before the real one exists (see the module docstring): every method of
    ``contract.ServicePort`` but ``check_token`` and ``health`` raises ``ServiceStarting``; the
    class is completed from the port when it is defined (``_complete_from_port``), so a method
    the port gains answers 503 here too, never an ``AttributeError`` (500)."""

    #: a stand-in is never done: the real service replaces it
    done = False

    def __init__(self, settings: ServiceSettings, waiting_for: str, *, environ: Mapping[str, str] | None = None) -> None:
        self.settings = settings
        self.token = resolve_token(settings, environ)
        self.fleet = settings.fleet
        self.waiting_for = waiting_for
        self.started_at = time.time()

    def check_token(self, token: str | None) -> None:
        check_token(self.token, token)

    def health(self) -> HealthDocument:
        return HealthDocument(status="degraded", uptime_s=round(time.time() - self.started_at, 1),
                              reasons=[f"starting: {self.waiting_for}"])

    def _starting(self, *args: Any, **kwargs: Any) -> Any:
        raise ServiceStarting(f"the service is starting: {self.waiting_for}")


def port_methods(port: type = ServicePort) -> list[str]:
    """The names of ``port``'s methods (its protocol classes', not ``object``'s or ``Protocol``'s)."""
    names: set[str] = set()
    for cls in port.__mro__:
        if cls in (object, Protocol, Generic) or not getattr(cls, "_is_protocol", False):
            continue
        names.update(name for name, value in vars(cls).items() if callable(value) and not name.startswith("_"))
    return sorted(names)


def _complete_from_port(cls: type) -> None:
    """Every port method ``cls`` does not define itself raises ``ServiceStarting``."""
    for name in port_methods():
        if name not in vars(cls):
            setattr(cls, name, cls._starting)  # type: ignore[attr-defined]


_complete_from_port(StartingService)


class ServiceSlot:
    """The service the API calls: first a ``StartingService``, then the real one (``current``)."""

    def __init__(self, current: Any) -> None:
        self.current = current

    def __getattr__(self, name: str) -> Any:
        return getattr(self.__dict__["current"], name)
