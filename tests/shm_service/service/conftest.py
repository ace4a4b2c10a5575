"""Fixtures of the service tests: a short simulated recording, a webhook receiver."""

from __future__ import annotations

from pathlib import Path

import pytest
from svc_helpers import Receiver

from shm_service.virtual_rig import SimulationSettings, simulate


@pytest.fixture(scope="session")
def short_recording(tmp_path_factory) -> Path:
    """150 s of ambient excitation with a 10 s rest and damage at 90 s (seeded)."""
    path = tmp_path_factory.mktemp("rec") / "short.mcap"
    simulate(SimulationSettings(duration=150.0, rest=10.0, excitation="ambient", seed=3,
                                damage=("mass:0.126@4.0",), damage_at=90.0), path)
    return path


@pytest.fixture()
def receiver():
    r = Receiver()
    yield r
    r.close()


@pytest.fixture(params=["sqlite", "postgres"])
def storage_target(request, tmp_path) -> str:
    """Where a storage test's database lives: a SQLite file, or a PostgreSQL database of its own
    in the session's server (``fresh_postgres_url``): the same test runs against both engines."""
    if request.param == "sqlite":
        return str(tmp_path / "s.sqlite")
    return request.getfixturevalue("fresh_postgres_url")
