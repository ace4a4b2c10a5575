"""The runtime's ports: the one-process service and the front of a fleet's worker processes both
implement ``contract.ServicePort`` (what every HTTP router and the dashboard are typed against)."""

from __future__ import annotations

import inspect

import pytest
from svc_helpers import fast_overrides

from contract import ServicePort, StructurePort
from shm_service.service import MonitoringService, load_settings
from shm_service.service.runtime._workers import WorkerFleet


def _port_methods(port: type) -> dict[str, inspect.Signature]:
    return {name: inspect.signature(getattr(port, name)) for name in dir(port)
            if not name.startswith("_") and callable(getattr(port, name, None))}


@pytest.mark.parametrize("cls", [MonitoringService, WorkerFleet])
def test_both_services_implement_every_method_of_the_port_with_its_parameters(cls):
    for name, wanted in _port_methods(ServicePort).items():
        method = getattr(cls, name, None)
        assert method is not None, f"{cls.__name__} lacks {name}()"
        got = inspect.signature(method)
        assert list(got.parameters) == list(wanted.parameters), (cls.__name__, name, got, wanted)
    assert isinstance(cls.done, property)


def test_a_running_service_of_one_structure_is_a_service_port(tmp_path):
    settings = load_settings(None, {**fast_overrides(tmp_path), "source": {"spec": "ingest"}, "archive": {"enabled": False}})
    service = MonitoringService(settings, environ={})
    try:
        assert isinstance(service, ServicePort) and isinstance(service, StructurePort)
        assert not service.fleet
    finally:
        service.stop(drain_s=0)


def test_the_front_of_worker_processes_is_a_service_port(tmp_path):
    settings = load_settings(None, {**fast_overrides(tmp_path), "workers": 2, "archive": {"enabled": False},
                                    "structures": [{"id": "a", "source": "ingest"}, {"id": "b", "source": "ingest"}]})
    front = WorkerFleet(settings, environ={})  # not started: no worker process
    try:
        assert isinstance(front, ServicePort) and front.fleet
    finally:
        front.storage.close()
