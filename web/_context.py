"""What one browser's view is given: a small typed context instead of the whole dashboard, and
the view settings its parts (scene, plots, panels) share."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

from contract import AlarmDocument, StructuresDocument, StructureSummaryDocument

if TYPE_CHECKING:
    from ._feed import StructureFeed

__all__ = ["DashboardStats", "Structures", "ViewContext", "ViewSettings"]

#: Trend windows the operator can choose (s).
TREND_WINDOWS = {"10 min": 600.0, "1 h": 3600.0, "6 h": 6 * 3600.0, "24 h": 86400.0, "7 days": 7 * 86400.0, "all": math.inf}


@dataclass(frozen=True)
class DashboardStats:
    """How the dashboard itself does (the status tab's last line)."""

    clients: int
    last_frame_s: float


class Structures(Protocol):
    """What a view reads of the service's structures: the overview and the feeds of those shown
    (``web._poller.PortPoller`` implements it)."""

    overview: StructuresDocument | None
    overview_error: str | None
    overview_version: int

    def ids(self) -> list[str]:
        """The structures' ids, as the overview lists them."""
        ...

    def summary(self, structure_id: str | None) -> StructureSummaryDocument | None:
        """The overview's line of ``structure_id`` (None: none)."""
        ...

    def feed(self, structure_id: str) -> "StructureFeed | str | None":
        """Its feed, the reason it cannot be drawn, or None while it is read (asking keeps it read)."""
        ...


@dataclass(frozen=True)
class ViewContext:
    """What a browser's view needs of the dashboard.

    label : the dashboard's title.
    fleet : the service monitors a fleet: the view shows a structure selector and the overview.
    structures : the overview and the feeds of the structures shown.
    acknowledge : acknowledge an alarm ``(alarm_id, token)`` as the dashboard (the service's rules:
        ``PermissionError``, ``KeyError``).
    stats : the dashboard's own figures, now.
    """

    label: str
    fleet: bool
    structures: Structures
    acknowledge: Callable[[int, str], AlarmDocument]
    stats: Callable[[], DashboardStats]


@dataclass
class ViewSettings:
    """One browser's view settings and what must be redrawn (shared by the view's parts; the
    render thread and viser's callbacks set plain attributes only)."""

    paused: bool = False
    elastic_scale: float = 20.0
    rigid_scale: float = 1.0
    units_shown: set[int] = field(default_factory=set)
    trend_window_s: float = TREND_WINDOWS["1 h"]
    dirty_scene: bool = True
    dirty_trends: bool = True
    dirty_spectra: bool = True
