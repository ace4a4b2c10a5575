"""The Loads tab of a structure with hot spots: the stress and strain envelopes along the beam,
each hot spot's consumed life and remaining life, and the trends of the damage-equivalent stress
ranges (DEL) and of the consumed life."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ._data import LoadsRecord
from ._html import LOADS_INTRO, angles_html, hot_spots_html, message_html
from ._plots import colour, scales_of, set_scales

if TYPE_CHECKING:
    from ._feed import Snapshot, StructureFeed

__all__ = ["LoadsPanel", "envelope_plot"]

NAN = float("nan")


def envelope_plot(record: LoadsRecord, hot_spots: list[tuple[str, float]]) -> tuple[np.ndarray, ...]:
    """uPlot data (η, largest stress range MPa, hot spots marker) along the beam: the hot spots'
    positions are added to the stations (uPlot shares one x), the range interpolated there, and
    the marker series is the range at a hot spot and NaN (not drawn) elsewhere."""
    x = record.positions_m
    y = record.stress_range_max_pa / 1e6
    spots = np.array([p for _, p in hot_spots], dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    if spots.size and keep.sum() >= 1:
        xs = np.union1d(x[keep], spots)
        ys = np.interp(xs, x[keep], y[keep])
    else:
        xs, ys = x, y
    marker = np.full(xs.shape, NAN)
    for p in spots:
        k = int(np.argmin(np.abs(xs - p))) if xs.size else -1
        if k >= 0:
            marker[k] = ys[k]
    return xs, ys, marker


class LoadsPanel:
    """The Loads tab's content (built in the tab's context; DEL plots added once their
    exponents are known)."""

    def __init__(self, gui: Any, tab: Any, feed: "StructureFeed") -> None:
        self.gui, self.tab, self.feed = gui, tab, feed
        self.names = [h.name for h in feed.rig.hot_spots]
        self.hot_spots = [(h.name, float(h.position)) for h in feed.rig.hot_spots]
        self._version = -1
        gui.add_markdown(LOADS_INTRO)
        # a biaxial beam: each hot spot's angle around the section (a girth weld's worst point)
        self.angles = gui.add_html(angles_html(list(feed.rig.hot_spots), {})) if feed.biaxial else None
        self.table = gui.add_html(message_html("Waiting for the structure's loads…"))
        x0, z = np.array([0.0, feed.length]), np.zeros(2)
        self.stress = gui.add_uplot(
            data=(x0, z, z), series=({"label": "η m"}, {"label": "largest stress range MPa", "stroke": "#b91c1c", "width": 2},
                                     {"label": "hot spots", "stroke": "#111111", "width": 0, "points": {"show": True, "size": 9}}),
            scales={"x": {"time": False}}, title="Stress envelope: largest range (MPa) along η (m)",
            height=170, visible=False, legend={"live": False})
        self.strain = gui.add_uplot(
            data=(x0, z, z), series=({"label": "η m"}, {"label": "largest strain range µε", "stroke": "#0f766e", "width": 2},
                                     {"label": "RMS strain µε", "stroke": "#14b8a6", "width": 1.5, "dash": (5, 4)}),
            scales={"x": {"time": False}}, title="Strain envelope along the beam (µm/m)", height=150, visible=False,
            legend={"live": False})
        self.consumed = gui.add_uplot(
            data=(x0,) + (z,) * len(self.names), series=({"label": "time"},) + tuple(
                {"label": f"D {n}", "stroke": colour(k), "width": 1.5} for k, n in enumerate(self.names, start=1)),
            scales={"x": {"time": False}}, title="Consumed life D per hot spot (Miner sum)", height=140, visible=False,
            legend={"live": False})
        self.dels: dict[str, Any] = {}

    def render(self, snap: "Snapshot") -> None:
        if self.angles is not None:
            text = angles_html(list(self.feed.rig.hot_spots), self.feed.hot_spot_angles())
            if text != self.angles.content:
                self.angles.content = text
        if snap.loads_version == self._version:
            return
        self._version = snap.loads_version
        record = snap.loads
        if record is None:
            self.table.content = hot_spots_html(_EMPTY, snap.loads_error) if snap.loads_error else self.table.content
            return
        self.table.content = hot_spots_html(record, snap.loads_error)
        if record.positions_m.size >= 2:
            self.stress.data = data = envelope_plot(record, self.hot_spots)
            set_scales(self.stress, scales_of(False, *data[1:]))
            self.stress.visible = bool(np.isfinite(record.stress_range_max_pa).any())
            self.strain.data = data = (record.positions_m, 1e6 * record.strain_range_max, 1e6 * record.strain_rms)
            set_scales(self.strain, scales_of(False, *data[1:]))
            self.strain.visible = bool(np.isfinite(record.strain_range_max).any())
        if record.t_s.size:
            self._render_trends(record)

    def _x(self, t: np.ndarray) -> tuple[np.ndarray, bool]:
        if t.size == 1:  # uPlot needs two x values to draw a range
            return np.array([t[0] - 1.0, t[0]]), True
        return t, False

    def _render_trends(self, record: LoadsRecord) -> None:
        x, doubled = self._x(record.t_s)
        time_axis = bool(x[-1] > 1e9)

        def column(v: np.ndarray) -> np.ndarray:
            return np.repeat(v, 2) if doubled else v

        self.consumed.data = data = (x, *(column(record.consumed.get(n, np.full(record.t_s.size, NAN))) for n in self.names))
        set_scales(self.consumed, scales_of(time_axis, *data[1:]))
        self.consumed.visible = True
        for m, by_name in record.dels_pa.items():
            plot = self.dels.get(m) or self._add_del_plot(m)
            plot.data = data = (x, *(column(by_name.get(n, np.full(record.t_s.size, NAN)) / 1e6) for n in self.names))
            set_scales(plot, scales_of(time_axis, *data[1:]))
            plot.visible = True

    def _add_del_plot(self, m: str) -> Any:
        with self.tab:
            plot = self.dels[m] = self.gui.add_uplot(
                data=(np.array([0.0, 1.0]),) + (np.zeros(2),) * len(self.names),
                series=({"label": "time"},) + tuple({"label": f"{n} MPa", "stroke": colour(k), "width": 1.5,
                                                     "points": {"show": True, "size": 4}}
                                                    for k, n in enumerate(self.names, start=1)),
                scales={"x": {"time": False}}, title=f"Damage-equivalent stress range per window, m = {m} (MPa)",
                height=140, visible=False, legend={"live": False})
        return plot


_EMPTY = LoadsRecord(design_life_years=None, hot_spots=(), positions_m=np.zeros(0), stress_range_max_pa=np.zeros(0),
                     strain_range_max=np.zeros(0), strain_rms=np.zeros(0), t_s=np.zeros(0), dels_pa={}, consumed={},
                     windows=0, truncated=False)
