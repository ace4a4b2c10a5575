"""`shm estimate` of a biaxial beam: both planes scored (rmse.e_xi_m), the estimate recording's ξ
keys, --modes-xi, and its refusal on a planar beam."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from shm_service.cli import main

MAST = Path(__file__).resolve().parents[2] / "examples" / "mast" / "rig.json"


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def biaxial_mast() -> dict:
    """The example mast bending in both planes, a gauge pair at 0° and 90° at each gauge's height."""
    data = json.loads(MAST.read_text())
    data["beam"]["bending"] = "biaxial"
    gauges = [s for s in data["sensors"] if s["kind"] == "strain"]
    data["sensors"] = [s for s in data["sensors"] if s["kind"] != "strain"]
    for s in gauges:
        data["sensors"] += [dict(s), {**s, "name": f"{s['name']}x", "angle_deg": 90}]
    return data


@pytest.fixture(scope="module")
def biaxial_recording(tmp_path_factory):
    """40 s of the biaxial mast in its veering wind."""
    folder = tmp_path_factory.mktemp("biaxial")
    data = biaxial_mast()
    data["simulator"]["rest"] = 10.0  # the wind starts after 10 s of rest
    rig = folder / "rig.json"
    rig.write_text(json.dumps(data))
    path = folder / "mast.mcap"
    assert main(["simulate", "--rig", str(rig), "--duration", "40", "--seed", "2", "--excitation", "ambient",
                 "--out", str(path)]) == 0
    return path


def test_estimate_scores_both_planes_and_writes_the_xi_keys(capsys, biaxial_recording, tmp_path):
    out_path = tmp_path / "est.mcap"
    code, out, _ = run(capsys, "estimate", str(biaxial_recording), "--json", "--out", str(out_path))
    assert code == 0
    data = json.loads(out)
    assert {"e_m", "e_xi_m", "deflection_xi_m", "curvature_xi_per_m"} <= set(data["rmse"])
    assert data["modes"] == 4 and data["modes_xi"] == 4 and data["selection"]["aided_xi"] == [1, 2, 3, 4]
    assert len(data["selection"]["gauges"]) == 8  # a biaxial beam's default: four gauges per plane
    from shm_service.processing.estimation import truth_from_recording
    from shm_service.recording import read_recording

    truth = truth_from_recording(read_recording(biaxial_recording))
    after = truth.t > 15.0
    assert data["rmse"]["e_xi_m"] < 0.05 * float(np.sqrt(np.mean(truth.e_xi[after] ** 2)))
    estimates = read_recording(out_path).channels["/estimate/state"]
    for key in ("b_xi[3]", "e_xi", "deflection_xi[9]", "curvature_xi[0]"):
        assert key in estimates.fields
    assert "b_xi[4]" not in estimates.fields
    # its virtual loads: each station at its angle around the section (the grid's at 0, the +ζ face)
    est = read_recording(out_path)
    loads = est.metadata["loads"]
    angles, names = json.loads(loads["angles_deg"]), json.loads(loads["names"])
    assert len(angles) == len(names) and angles[len(names) - 16:] == [0.0] * 16
    assert est.channels["/estimate/loads"].values.shape[0] == estimates.values.shape[0]


def test_modes_xi_sets_the_xi_unit_deformations(capsys, biaxial_recording):
    code, out, _ = run(capsys, "estimate", str(biaxial_recording), "--json", "--modes-xi", "3")
    assert code == 0
    data = json.loads(out)
    assert data["modes"] == 4 and data["modes_xi"] == 3 and data["selection"]["aided_xi"] == [1, 2, 3]


def test_modes_xi_on_a_planar_recording_is_refused(capsys, tmp_path):
    path = tmp_path / "planar.mcap"
    assert main(["simulate", "--rig", str(MAST), "--duration", "5", "--out", str(path)]) == 0
    capsys.readouterr()
    code, _, err = run(capsys, "estimate", str(path), "--modes-xi", "2")
    assert code == 2
    assert "modes_xi=2: unit deformations in ξ need a beam that bends in both planes" in err


def test_the_service_configuration_sets_modes_xi_for_a_biaxial_rig_and_ignores_it_for_a_planar_one():
    from contract import parse_rig
    from shm_service.service._config import EstimatorSettings
    from shm_service.service.runtime._structure import _ModelCache

    planar = _ModelCache().get(parse_rig(json.loads(MAST.read_text())), EstimatorSettings(modes_xi=3))
    assert not planar.biaxial and planar.gamma == 4 and len(planar.selection.gauges) == 4
    data = biaxial_mast()
    model = _ModelCache().get(parse_rig(data), EstimatorSettings(modes_xi=3))
    assert model.gamma == 4 and model.gamma_xi == 3 and len(model.selection.gauges) == 8
    assert _ModelCache().get(parse_rig(data), EstimatorSettings()).gamma_xi == 4  # default: as modes
