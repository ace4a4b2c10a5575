"""The ports of the runtime: what the HTTP routers and the dashboard may ask of a running service.

``MonitoringService`` (one process) and ``WorkerFleet`` (a front over worker processes) both
implement ``ServicePort``; the routers of ``/api/structures/{id}/...`` and the dashboard's
structure views read one structure through ``StructurePort``. A structure of one is a fleet of
one to these ports: the same pull path for both.

Conventions of every method: thread-safe; an unknown structure id raises ``KeyError``; a known
structure that cannot answer (its worker process ended, it failed to start) raises a
``LookupError`` that is not a ``KeyError`` (``StructureUnavailable``); a wrong or missing token
raises ``PermissionError``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Generic, Protocol, TypeVar, runtime_checkable

import numpy as np

from ._documents import (
    AlarmDocument,
    BaselineRequestDocument,
    FatigueDocument,
    HealthDocument,
    IngestResultDocument,
    LiveEstimatesDocument,
    SpectrumDocument,
    StatusDocument,
    StructuresDocument,
    TrendRow,
    WindowDocument,
)
from ._rig import RigDescription
from ._state import StateLayout

__all__ = ["MAX_PAGE", "Lane", "LanePool", "NotSingleStructure", "Page", "ServicePort", "ServiceStarting", "StructureHost", "StructureModel", "StructurePort", "StructureUnavailable", "Waker"]

T = TypeVar("T")


class ServiceStarting(RuntimeError):
    """The service is not built yet (the message says what it waits for): retry later (503)."""


class StructureUnavailable(LookupError):
    """The structure exists but cannot answer (its start failed: the message says why)."""


class NotSingleStructure(LookupError):
    """A single-structure request to a fleet (the message names the fleet's routes)."""

#: The most rows one page of a list route holds (``limit``; the default is 1000). A page is
#: streamed, so even the largest one costs the server a bounded amount of memory.
MAX_PAGE = 1_000_000


@dataclass
class Page(Generic[T]):
    """One page of a list (trend rows, alarms, ...), the paging convention of every list route.

    ``items`` is lazy (a page of a million rows is read from the database while it is sent) and
    may be iterated once; whoever does not exhaust it calls ``close()``. ``count`` items follow;
    ``total`` match the query on all pages; ``truncated``: more follow this page, from
    ``next_cursor`` (an opaque string: pass it back as ``cursor``). A cursor this service did not
    issue raises ``ValueError`` naming it."""

    items: Iterator[T]
    count: int
    total: int
    truncated: bool
    next_cursor: str | None
    close: Callable[[], None] = field(default=lambda: None, repr=False)

    def __iter__(self) -> Iterator[T]:
        return self.items



@dataclass(frozen=True)
class StructureModel:
    """What a dashboard draws one structure with: its rig (length, support, orientation, sensors),
    the model's unit deformations (``estimator.UnitDeformations``), the state layout its estimates
    are read through and the stations of the curvature index (m); for a beam that bends in two
    planes also the ξ plane's unit deformations (None for a planar one)."""

    id: str
    rig: RigDescription
    units: Any
    layout: StateLayout
    stations: np.ndarray
    units_xi: Any = None


@runtime_checkable
class StructurePort(Protocol):
    """One structure of a service, by its id (as ``GET /api/structures`` lists them)."""

    def structure_status(self, structure_id: str) -> StatusDocument:
        """As ``GET /api/structures/{id}/status``."""
        ...

    def structure_trends(self, structure_id: str, from_s: float | None, to_s: float | None, mode: int | None = None,
                         limit: int = 100_000) -> list[TrendRow]:
        """Its trend rows with ``from_s <= window_start_s < to_s`` (UNIX s; None: open)."""
        ...

    def structure_alarms(self, structure_id: str, state: str | None = None) -> list[AlarmDocument]:
        """Its alarms, newest first."""
        ...

    def structure_fatigue(self, structure_id: str, from_s: float | None = None, to_s: float | None = None,
                          limit: int = 100_000) -> FatigueDocument:
        """Its hot spots' loads and life, the per-window trend with ``from_s <= start_s < to_s``
        (UNIX s; None: open) and the strain envelope of those windows."""
        ...

    def structure_trends_page(self, structure_id: str, from_s: float | None, to_s: float | None, mode: int | None = None,
                              *, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        """A page of its trend rows (``GET /api/structures/{id}/trends``), after ``cursor``."""
        ...

    def structure_alarms_page(self, structure_id: str, state: str | None = None, *, limit: int = 1000,
                              cursor: str | None = None) -> Page[AlarmDocument]:
        """A page of its alarms, newest first, after ``cursor``."""
        ...

    def structure_spectra(self, structure_id: str) -> SpectrumDocument | None:
        """Its latest window's spectra (None before its first window)."""
        ...

    def structure_window(self, structure_id: str) -> WindowDocument | None:
        """Its latest committed analysis window (modes, charts, curvature along the stations);
        None before its first window."""
        ...

    def structure_rig(self, structure_id: str) -> RigDescription:
        """Its rig description."""
        ...

    def structure_model(self, structure_id: str) -> StructureModel:
        """How to draw it (built once per distinct rig and estimator settings)."""
        ...

    def live(self, structure_id: str, after: int = 0) -> LiveEstimatesDocument:
        """Its estimates newer than ``after`` (a sequence number); a call keeps the structure
        keeping them for a while: a structure nobody polls keeps none."""
        ...

    def request_baseline(self, structure_id: str | None = None) -> BaselineRequestDocument:
        """Learn a new baseline from its next windows."""
        ...

    def ingest(self, document: Any, structure_id: str | None = None) -> IngestResultDocument | None:
        """Take a batch of samples (``POST .../ingest``); None: the structure's queue is full."""
        ...


@runtime_checkable
class ServicePort(StructurePort, Protocol):
    """A running service: its structures (``StructurePort``), the stored rows of all of them,
    its health and its life cycle."""

    token: str | None
    fleet: bool

    def check_token(self, token: str | None) -> None:
        """Raise ``PermissionError`` unless ``token`` is the service's."""
        ...

    def health(self) -> HealthDocument: ...

    def status(self, structure_id: str | None = None) -> StatusDocument:
        """As ``GET /api/status`` (one structure's service) or of ``structure_id``."""
        ...

    def structures_document(self) -> StructuresDocument:
        """As ``GET /api/structures`` (state, lag, windows, active alarms of each)."""
        ...

    def trends(self, from_s: float | None, to_s: float | None, mode: int | None = None, source: str | None = None,
               limit: int = 100_000) -> list[TrendRow]: ...

    def alarms(self, state: str | None = None) -> list[AlarmDocument]: ...

    def fatigue(self, structure_id: str | None = None, from_s: float | None = None, to_s: float | None = None,
                limit: int = 100_000) -> FatigueDocument:
        """As ``structure_fatigue`` of ``structure_id``; None: the service's one structure (a fleet
        raises ``LookupError`` as ``status(None)`` does: ask per structure)."""
        ...

    def trends_page(self, from_s: float | None, to_s: float | None, mode: int | None = None, source: str | None = None,
                    *, limit: int = 1000, cursor: str | None = None) -> Page[TrendRow]:
        """A page of the trend rows of all structures (``GET /api/trends``), after ``cursor``."""
        ...

    def alarms_page(self, state: str | None = None, *, limit: int = 1000, cursor: str | None = None) -> Page[AlarmDocument]:
        """A page of the alarms of all structures, newest first (``GET /api/alarms``)."""
        ...

    def acknowledge(self, alarm_id: int, token: str, by: str) -> AlarmDocument:
        """Acknowledge an alarm as ``by``; ``KeyError`` when it does not exist."""
        ...

    def spectra(self, structure_id: str | None = None) -> SpectrumDocument | None: ...

    def fleet_metrics(self) -> str:
        """The Prometheus exposition of ``/metrics``."""
        ...

    def start(self) -> None: ...

    def stop(self, *, drain_s: float = 2.0) -> Any: ...

    def wait(self, timeout: float | None = None) -> bool: ...

    @property
    def done(self) -> bool: ...


class Lane(Protocol):
    """One lane of a structure on a pool of threads: ``ready()`` (cheap, called under the pool's
    lock) says whether ``step()`` has work; ``step()`` does one unit of it (and handles its own
    errors); ``finished`` removes the lane for good; ``background`` (optional, default False):
    taken only when no other lane is ready."""

    name: str
    finished: bool

    def ready(self) -> bool: ...
    def step(self) -> None: ...


class Waker(Protocol):
    """Something that sleeps until there may be work: ``wake()`` says there may be some now."""

    def wake(self) -> None: ...


class LanePool(Waker, Protocol):
    """The pool a structure's lanes (and its source's) are stepped on; ``wake()``: a lane may be
    ready now."""

    def add(self, lane: Lane) -> None: ...


class StructureHost(Protocol):
    """What a structure needs of the service that runs it, and nothing more: whether it is one of
    a fleet, how long a ``follow:`` source waits for its file's rig, the pool its lanes run on and
    the notifier its committed windows and alarms wake."""

    @property
    def fleet(self) -> bool: ...

    @property
    def rig_wait_s(self) -> float: ...

    @property
    def scheduler(self) -> LanePool: ...

    @property
    def notifier(self) -> Waker: ...
