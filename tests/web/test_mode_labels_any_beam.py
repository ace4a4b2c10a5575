"""The dashboard labels spectra and mode switches by the model's modes on any beam: the mast's
unit deformations are its own clamped modes (b_k is mode k, at the section model's frequencies),
not the laboratory sheet's."""

from __future__ import annotations

import numpy as np
import pytest
from example_mast import planar_mast_data

import estimator
from contract import StateLayout, parse_rig
from web import StructureFeed


def test_the_masts_spectra_are_labelled_by_its_own_modes():
    rig = parse_rig(planar_mast_data())  # the planar estimator's unit deformations b1..b4
    model = estimator.build_model(rig, peripheral="gyro", modes=4, imus=4, tofs=0, gauges=4)
    feed = StructureFeed(rig=rig, units=model.units, layout=StateLayout("gyro", 4, 4), stations=np.linspace(2.0, 20.0, 10))
    assert [feed.mode_map.unit_label(k) for k in range(1, 5)] == [f"b{k} · mode {k}" for k in range(1, 5)]
    # the label's model frequencies are the tapered tube's eigenfrequencies (shm modes on the same rig)
    exact = estimator.natural_modes(estimator.assemble_beam(rig), 4).frequencies_hz
    np.testing.assert_allclose([f for (f,) in feed.units.frequencies_hz], exact, rtol=1e-9)
    assert exact[0] == pytest.approx(1.54, abs=0.01)  # a 20 m steel mast, not the 4 m sheet's 0.3 Hz
