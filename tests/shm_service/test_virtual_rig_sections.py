"""The virtual rig's plant built from ``beam.sections``: its gauges read −c(η)·κ with the section's c."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from contract import parse_rig
from estimator import assemble_beam, natural_modes
from shm_service.virtual_rig import SimulationSettings, VirtualRig

MAST = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"


def test_the_plant_of_a_tapered_mast_has_its_modes_and_its_gauges_read_the_fibre_distance():
    data = json.loads(MAST.read_text())
    # gauges on truth stations: 4 m (D = 0.44 m) and 14 m (beyond the 8 m joint: D = 0.29 m)
    data["sensors"] = [s for s in data["sensors"] if s["kind"] != "strain"] + [
        {"name": "a", "kind": "strain", "position": 4.0}, {"name": "b", "kind": "strain", "position": 14.0}]
    rig = parse_rig(data)
    settings = SimulationSettings(duration=30.0, excitation="ambient", support="clamped", orientation="standing",
                                  length=20.0, rest=2.0, ideal=True, seed=4)
    plant = VirtualRig(settings, rig)
    exact = natural_modes(assemble_beam(rig), 4).frequencies_hz
    truth = json.loads(plant.truth_metadata()["eigenfrequencies_hz"])
    assert np.array(truth[:4]) == pytest.approx(exact, rel=1e-4)  # ideal: the plant is the nominal rig
    strain = {"a": [], "b": []}
    curvature = {"a": [], "b": []}
    stations = list(rig.truth_stations)
    for block in plant.blocks(10.0):
        kappa = block.truth["curvature"]
        for name, eta in (("a", 4.0), ("b", 14.0)):
            strain[name].append(block.measurements[f"/strain/{name}"][1][:, 0])
            curvature[name].append(kappa[:, stations.index(eta)])
    for name, outer in (("a", 0.44), ("b", 0.29)):
        eps, kap = np.concatenate(strain[name]), np.concatenate(curvature[name])
        slope = np.dot(eps - eps.mean(), kap - kap.mean()) / np.dot(kap - kap.mean(), kap - kap.mean())
        assert slope == pytest.approx(-0.5 * outer, rel=1e-3)  # ε = −c κ (measured: within 3e-5, the gauge noise)
