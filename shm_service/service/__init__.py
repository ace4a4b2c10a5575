"""``shm serve``: the continuous monitoring service (sources, pipeline, storage, alarms, API).

The names below load on first use: ``shm --help`` imports this package to register ``serve``
and must not pay for pydantic and the contract's documents.
"""

from __future__ import annotations

from typing import Any

#: What embeds the service in a program (and what its tests use): the service and its settings, the
#: HTTP app and a server for it, the storage, and ``start_serve`` for ``shm serve`` as a process.
_HOMES = {
    # the service and its configuration
    "MonitoringService": "runtime._service", "ServiceError": "runtime._service",
    "ServiceSettings": "_config", "SettingsError": "_config", "load_settings": "_config", "render_toml": "_config",
    "resolve_token": "_config", "AlarmSettings": "_config", "DashboardSettings": "_config",
    "EstimatorSettings": "_config", "ServerSettings": "_config", "StructureSettings": "_config",
    # the sections a part defines for itself (the configuration is made of them)
    "ArchiveSettings": "stages._archive", "NotifySettings": "alarms._notify", "RetentionSettings": "storage._retention",
    "SimSettings": "sources._settings", "SourceSettings": "sources._settings",
    # the HTTP API over a service
    "create_app": "http._app", "ApiServer": "http._server",
    # the database
    "Storage": "storage._storage", "StorageUnavailable": "storage._storage", "WindowCommit": "storage._storage", "AlarmChange": "storage._storage",
    "SCHEMA_VERSION": "storage._storage",
    # shm serve as a process
    "SENSOR_STATES": "runtime._dashboard_port", "ServeProcess": "runtime._launch", "ServeStartError": "runtime._launch",
    "start_serve": "runtime._launch", "read_ready": "runtime._processes",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        import importlib

        return getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
