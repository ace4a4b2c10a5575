"""``shm serve``: the continuous monitoring service (sources, pipeline, storage, alarms, API).

The names below load on first use: ``shm --help`` imports this package to register ``serve``
and must not pay for pydantic and the contract's documents.
"""

from __future__ import annotations

from typing import Any

__all__ = ["SENSOR_STATES", "ServeProcess", "ServeStartError", "read_ready", "start_serve"]

_HOMES = {"SENSOR_STATES": "_dashboard_port", "ServeProcess": "_launch",
          "ServeStartError": "_launch", "start_serve": "_launch", "read_ready": "_processes"}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        import importlib

        return getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
