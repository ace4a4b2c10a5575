"""The mast of ``examples/mast/rig.json`` and its planar copy.

The example bends in both planes (a gauge pair at 0° and 90° at each of four heights, a veering
wind). The tests of planar figures of the mast (one plane's modes, Γ gauges for Γ modes, the
planar estimator's selection) use the same mast bending in ζ alone: the description as it was
before it became biaxial.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["MAST", "mast_data", "planar_mast_data", "write_planar_mast"]

#: the example's rig description
MAST = Path(__file__).resolve().parents[1] / "examples" / "mast" / "rig.json"


def mast_data() -> dict[str, Any]:
    """The example mast's description (a fresh dict)."""
    return json.loads(MAST.read_text())


def planar_mast_data() -> dict[str, Any]:
    """The example mast bending in ζ alone: ``bending`` planar, the gauges at 90° dropped (a planar
    beam has gauges at 0° and 180° only), the simulator's settings without the wind's veering
    direction and without the wind as the default excitation (``shm simulate``'s own default then)."""
    data = mast_data()
    data["beam"].pop("bending", None)
    data["sensors"] = [s for s in data["sensors"] if s.get("angle_deg", 0.0) in (0, 180)]
    for key in ("excitation", "wind_direction"):
        data.get("simulator", {}).pop(key, None)
    return data


def write_planar_mast(directory: Path) -> Path:
    """``planar_mast_data()`` written as ``directory/rig.json``; returns its path."""
    path = Path(directory) / "rig.json"
    path.write_text(json.dumps(planar_mast_data(), indent=2))
    return path
