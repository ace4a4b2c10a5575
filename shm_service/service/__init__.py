"""``shm serve``: the continuous monitoring service (sources, pipeline, storage, alarms, API).

The names below load on first use: ``shm --help`` imports this package to register ``serve``
and must not pay for pydantic and the contract's documents.
"""

from __future__ import annotations

from typing import Any

__all__ = ["DashboardService", "SENSOR_STATES"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from . import _dashboard_port

        return getattr(_dashboard_port, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
