"""The tip orbit of a beam that bends in two planes: its tip's ζ deflection against its ξ
deflection over the last minutes, the classic picture of a tower's motion (a line along the wind
for along-wind sway, an ellipse or a figure of eight for a tower that also sways across it).

uPlot draws its x axis sorted, so the orbit is drawn as points sorted by ξ (a scatter of the
tip's positions) with the newest one marked; both axes share one range, so a circle looks round.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np

from ._html import orbit_intro
from ._plots import set_scales

if TYPE_CHECKING:
    from ._feed import Estimate, StructureFeed

__all__ = ["ORBIT_S", "OrbitPanel", "orbit_plot"]

#: Data seconds of the orbit drawn, the tip positions kept per data second, and the redraws per wall second.
ORBIT_S, ORBIT_HZ, REDRAW_S = 180.0, 10.0, 0.5
NAN = float("nan")


def orbit_plot(zeta_mm: np.ndarray, xi_mm: np.ndarray) -> tuple[tuple[np.ndarray, ...], dict]:
    """uPlot data (ξ mm sorted, ζ mm, newest point) and scales (one symmetric range for both axes)
    of the tip positions (oldest first); the newest position is the third series (NaN elsewhere)."""
    z = np.asarray(zeta_mm, dtype=float)
    x = np.asarray(xi_mm, dtype=float)
    if z.shape != x.shape or z.ndim != 1:
        raise ValueError(f"zeta_mm {z.shape} and xi_mm {x.shape} must be 1-D of one length")
    if z.size == 0:
        return (np.array([-1.0, 1.0]), np.full(2, NAN), np.full(2, NAN)), _scales(1.0)
    order = np.argsort(x, kind="stable")
    newest = np.full(z.size, NAN)
    newest[int(np.flatnonzero(order == z.size - 1)[0])] = z[-1]
    reach = float(np.max(np.abs(np.concatenate([z, x]))))
    return (x[order], z[order], newest), _scales(1.1 * reach if reach > 0 else 1.0)


def _scales(r: float) -> dict:
    return {"x": {"time": False, "auto": False, "range": [-r, r]}, "y": {"auto": False, "range": [-r, r]}}


class OrbitPanel:
    """The Orbit tab: the tip positions of the estimates drawn, over the last ``ORBIT_S`` of data."""

    def __init__(self, gui: Any, feed: "StructureFeed") -> None:
        if feed.units_xi is None:
            raise ValueError("the tip orbit needs a beam that bends in two planes (units_xi)")
        self.tip = np.asarray(feed.units.shape(np.array([feed.length])), dtype=float)[0]
        self.tip_xi = np.asarray(feed.units_xi.shape(np.array([feed.length])), dtype=float)[0]
        self.kept: deque[tuple[float, float, float]] = deque()  # (t_s, Δζ mm, Δξ mm)
        self._drawn_at = -np.inf
        gui.add_markdown(orbit_intro(ORBIT_S))
        data, scales = orbit_plot(np.zeros(0), np.zeros(0))
        self.plot = gui.add_uplot(
            data=data, series=({"label": "Δξ tip mm"}, {"label": "Δζ tip mm", "stroke": "#2563eb", "width": 0,
                                                         "points": {"show": True, "size": 3, "fill": "#2563eb"}},
                               {"label": "now", "stroke": "#111111", "width": 0, "points": {"show": True, "size": 9, "fill": "#111111"}}),
            scales=scales, title="Tip orbit: Δζ (mm) against Δξ (mm)", height=320, legend={"live": False})
        self.count = 0  # tip positions drawn last

    def add(self, est: "Estimate") -> None:
        """Keep the tip position of a drawn estimate (at most ``ORBIT_HZ`` per data second)."""
        if self.kept and est.t_s - self.kept[-1][0] < 1.0 / ORBIT_HZ:
            return
        self.kept.append((float(est.t_s), 1e3 * float(self.tip @ est.state.b), 1e3 * float(self.tip_xi @ est.state.b_xi)))
        while self.kept and self.kept[0][0] < est.t_s - ORBIT_S:
            self.kept.popleft()

    def render(self, now: float) -> None:
        if now - self._drawn_at < REDRAW_S or not self.kept:
            return
        self._drawn_at = now
        arr = np.array(self.kept, dtype=float)
        data, scales = orbit_plot(arr[:, 1], arr[:, 2])
        self.plot.data = data
        set_scales(self.plot, scales)
        self.count = arr.shape[0]
