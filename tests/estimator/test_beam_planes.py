"""The FE beam of each bending plane of a biaxial beam (``assemble_beam(..., plane=...)``) and
`shm modes` listing both planes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from contract import RigError, parse_rig
from estimator import assemble_beam, natural_modes
from shm_service.cli import main

E, RHO = 2.1e11, 7850.0
WIDTH, THICKNESS = 0.06, 0.02


def rig(beam: dict, *, gravity: float = 0.0, point_masses=(), bending: str = "biaxial"):
    return parse_rig({"beam": {"length": 2.0, "bending": bending, **beam}, "gravity": gravity, "support": "clamped",
                      "point_masses": list(point_masses), "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]})


RECTANGLE = {"width": WIDTH, "thickness": THICKNESS, "youngs_modulus": E, "density": RHO}
TUBE = {"youngs_modulus": E, "density": RHO,
        "sections": [{"position": 0.0, "shape": "tube", "outer_diameter": 0.1, "wall_thickness": 0.004},
                     {"position": 2.0, "shape": "tube", "outer_diameter": 0.08, "wall_thickness": 0.003}]}


def test_a_clamped_uniform_rectangle_bends_in_xi_at_width_over_thickness_times_its_zeta_frequencies():
    # EI_ξ / EI_ζ = (t w³) / (w t³) = (w/t)², the same mass: every frequency scales by w/t, attached masses or not.
    described = rig(RECTANGLE, point_masses=[{"position": 2.0, "mass": 0.5, "rotary_inertia": 1e-4}])
    zeta = natural_modes(assemble_beam(described), 6).frequencies_hz
    xi_model = assemble_beam(described, plane="xi")
    assert xi_model.plane == "xi"
    xi = natural_modes(xi_model, 6).frequencies_hz
    # K_ξ = (w/t)² K_ζ exactly; the eigensolver resolves the lowest of the stiff mesh's eigenvalues to ~1e-8
    np.testing.assert_allclose(xi / zeta, WIDTH / THICKNESS, rtol=1e-7)
    np.testing.assert_array_equal(xi_model.mass, assemble_beam(described).mass)


def test_a_tube_bends_alike_in_both_planes():
    described = rig(TUBE, gravity=9.81)
    zeta, xi = assemble_beam(described), assemble_beam(described, plane="xi")
    np.testing.assert_array_equal(zeta.stiffness, xi.stiffness)
    np.testing.assert_array_equal(natural_modes(zeta).frequencies_hz, natural_modes(xi).frequencies_hz)


def test_the_xi_plane_of_a_table_is_the_zeta_plane_of_its_xi_properties():
    station = {"shape": "table", "mass_per_length": 5.0, "fibre_distance": 0.02, "fibre_distance_xi": 0.05}
    biaxial = rig({"sections": [{"position": 0.0, **station, "bending_stiffness": 6e4, "bending_stiffness_xi": 3.6e5},
                                {"position": 2.0, **station, "bending_stiffness": 2e4, "bending_stiffness_xi": 1.2e5}]})
    as_zeta = rig({"sections": [{"position": 0.0, **station, "bending_stiffness": 3.6e5},
                                {"position": 2.0, **station, "bending_stiffness": 1.2e5}]}, bending="planar")
    np.testing.assert_allclose(natural_modes(assemble_beam(biaxial, plane="xi")).frequencies_hz,
                               natural_modes(assemble_beam(as_zeta)).frequencies_hz, rtol=1e-12)
    # edgewise 6× as stiff as flapwise: √6 in every frequency
    np.testing.assert_allclose(natural_modes(assemble_beam(biaxial, plane="xi")).frequencies_hz
                               / natural_modes(assemble_beam(biaxial)).frequencies_hz, np.sqrt(6.0), rtol=1e-7)


def test_a_planar_beam_has_no_xi_model_and_an_unknown_plane_is_refused():
    planar = rig(RECTANGLE, bending="planar")
    with pytest.raises(RigError, match="plane='xi' is the second bending plane of a biaxial beam"):
        assemble_beam(planar, plane="xi")
    with pytest.raises(ValueError, match="plane='y' must be one of"):
        assemble_beam(planar, plane="y")


def _write(tmp_path, beam: dict, bending: str) -> str:
    path = tmp_path / f"{bending}.json"
    path.write_text(json.dumps({"beam": {"length": 2.0, "bending": bending, **beam}, "gravity": 0.0, "support": "clamped",
                                "sensors": [{"name": "D", "kind": "imu", "position": 0.0}]}))
    return str(path)


def test_shm_modes_lists_both_planes_of_a_biaxial_beam(tmp_path, capsys):
    biaxial = _write(tmp_path, RECTANGLE, "biaxial")
    assert main(["modes", "--rig", biaxial, "--count", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bending"] == "biaxial" and len(out["frequencies_xi_hz"]) == 4
    np.testing.assert_allclose(np.array(out["frequencies_xi_hz"]) / np.array(out["frequencies_hz"]), WIDTH / THICKNESS,
                               rtol=1e-5)  # the JSON rounds to 6 decimals
    assert main(["modes", "--rig", biaxial, "--count", "4"]) == 0
    text = capsys.readouterr().out
    assert "f ζ [Hz]" in text and "f ξ [Hz]" in text
    row = text.splitlines()[-4].split()
    assert row[0] == "1" and float(row[3]) == pytest.approx(out["frequencies_xi_hz"][0], abs=1e-4)


def test_shm_modes_of_a_planar_beam_has_no_xi_keys(tmp_path, capsys):
    assert main(["modes", "--rig", _write(tmp_path, RECTANGLE, "planar"), "--count", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "frequencies_xi_hz" not in out and "bending" not in out and len(out["frequencies_hz"]) == 4
