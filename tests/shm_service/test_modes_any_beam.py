"""`shm modes` on the shipped mast and blade examples against a shooting method (no FE).

The reference builds EI(x) and μ(x) from the stations of each ``rig.json`` with its own closed forms
(a tube's π/64 (D⁴ − d⁴), a table's linear interpolation) and solves
(EI w'')'' − (N w')' = ω² μ w by shooting (``tests/estimator/section_reference.py``).
"""

from __future__ import annotations

import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from shm_service.cli import main

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "estimator"))
from section_reference import frequencies as shooting_frequencies

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

#: The shooting reference's first six frequencies (Hz), recorded (python -m pytest this file; see docs/tutorials/any-beam.md).
RECORDED = {
    "mast": [1.5414119, 5.9820589, 14.642584, 27.950913, 45.650338, 67.980301],
    "blade": [5.0117531, 16.378160, 37.435051, 68.941716, 110.64674, 163.29002],
}


def _profile(rig: dict):
    beam = rig["beam"]
    stations = beam["sections"]
    E, rho = beam.get("youngs_modulus"), beam.get("density")

    def props(s: dict, t: float, n: dict) -> tuple[float, float]:
        lin = lambda key: s[key] + t * (n[key] - s[key])
        if s["shape"] == "tube":
            outer = lin("outer_diameter")
            inner = outer - 2 * lin("wall_thickness")
            return E * math.pi / 64 * (outer**4 - inner**4), rho * math.pi / 4 * (outer**2 - inner**2)
        if s["shape"] == "table":
            return lin("bending_stiffness"), lin("mass_per_length")
        raise AssertionError(s["shape"])

    def at(x: float, which: int) -> float:
        for a, b in itertools.pairwise(stations):
            if b["position"] > a["position"] and a["position"] <= x <= b["position"]:
                return props(a, (x - a["position"]) / (b["position"] - a["position"]), b)[which]
        raise AssertionError(x)

    breaks = [s["position"] for s in stations]
    return (lambda x: at(x, 0)), (lambda x: at(x, 1)), breaks


def _reference(name: str) -> tuple[np.ndarray, dict]:
    rig = json.loads((EXAMPLES / name / "rig.json").read_text())
    EI, mu, breaks = _profile(rig)
    g = rig["gravity"] * (1.0 if rig.get("orientation", "hanging") == "hanging" else -1.0)
    masses = [(m["position"], m["mass"]) for m in rig.get("point_masses", [])]
    assert all(m.get("rotary_inertia", 0.0) == 0.0 for m in rig.get("point_masses", []))
    ref = shooting_frequencies(6, f_max=250.0, samples=250, length=rig["beam"]["length"], EI=EI, mu=mu,
                               breaks=breaks, masses=masses, axial_gravity=g, support=rig["support"])
    return ref, rig


@pytest.mark.parametrize("name", ["mast", "blade"])
def test_shm_modes_on_the_example_matches_the_shooting_reference(name, capsys):
    ref, _ = _reference(name)
    code = main(["modes", "--rig", str(EXAMPLES / name / "rig.json"), "--count", "6", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert np.array(out["frequencies_hz"]) == pytest.approx(ref, rel=1e-4)
    if name == "mast":  # a round tube bending in both planes: ξ has the same frequencies as ζ
        assert np.array(out["frequencies_xi_hz"]) == pytest.approx(ref, rel=1e-4)
    else:
        assert "frequencies_xi_hz" not in out
    if RECORDED[name]:
        assert ref == pytest.approx(RECORDED[name], rel=1e-6)


@pytest.mark.parametrize("name", ["mast", "blade"])
def test_the_examples_serve_configuration_and_rig_load(name):
    from contract import load_rig
    from shm_service.service import load_settings

    settings = load_settings(EXAMPLES / name / "serve.toml")
    assert settings.source.rig == f"examples/{name}/rig.json"
    assert settings.estimator.tofs == 0  # neither has a reflector
    rig = load_rig(EXAMPLES / name / "rig.json")
    assert rig.support == "clamped" and rig.beam.sections is not None
    assert rig.reflector_distance is None and not rig.sensors_of("tof") and not rig.sensors_of("bearing")
    assert settings.estimator.gauges == len(rig.sensors_of("strain"))
    assert settings.estimator.imus == len([s for s in rig.sensors_of("imu") if s.name != "D"])


def test_the_blade_stiffness_falls_two_orders_of_magnitude_and_the_mast_tapers():
    from contract import load_rig

    blade = load_rig(EXAMPLES / "blade" / "rig.json").beam
    assert blade.bending_stiffness(0.0) / blade.bending_stiffness(8.0) == pytest.approx(100.0)
    mast = load_rig(EXAMPLES / "mast" / "rig.json")
    assert mast.orientation == "standing"
    assert mast.beam.fibre_distance([0.0, 20.0]) == pytest.approx([0.25, 0.1])
    spots = json.loads((EXAMPLES / "mast" / "rig.json").read_text())["hot_spots"]
    assert {h["name"]: h["curve"] for h in spots} == {"base_flange_weld": "EN1993-1-9:71", "door_opening": "EN1993-1-9:90"}
