"""One browser's view: the structure it shows (its scene, plots and panels) and what it redraws
each frame. It is given a ``ViewContext`` (``web._context``), never the dashboard."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import viser

from ._context import ViewContext, ViewSettings
from ._html import HeaderInfo, header_html
from ._loads import LoadsPanel
from ._orbit import OrbitPanel
from ._panels import AlarmsPanel, ControlsPanel, SettingsPanel, StatusPanel
from ._plots import SpectraPanel, TrendsPanel
from ._scene import SceneView, camera_of

if TYPE_CHECKING:
    from ._feed import Snapshot, StructureFeed

__all__ = ["ClientView"]

SPECTRA_MIN_PERIOD_S = 0.5
TEXT_MIN_PERIOD_S = 0.25


class _Shown:
    """The parts of the view that belong to the structure shown (rebuilt on a switch)."""

    def __init__(self, client: viser.ClientHandle, ctx: ViewContext, feed: "StructureFeed", settings: ViewSettings) -> None:
        gui = client.gui
        self.feed = feed
        self.scene = SceneView(client.scene, feed)
        self.tabs = tabs = gui.add_tab_group(order=3)
        with tabs.add_tab("Spectra", viser.Icon.WAVE_SINE):
            self.spectra = SpectraPanel(gui, feed)
        with tabs.add_tab("Trends", viser.Icon.CHART_LINE):
            self.trends = TrendsPanel(gui, feed)
        self.loads: LoadsPanel | None = None
        if feed.rig.hot_spots:  # only a structure with fatigue details has loads to show
            with tabs.add_tab("Loads", viser.Icon.WEIGHT) as tab:
                self.loads = LoadsPanel(gui, tab, feed)
        self.orbit: OrbitPanel | None = None
        if feed.biaxial:  # a beam that bends in two planes: its tip's orbit
            with tabs.add_tab("Orbit", viser.Icon.CIRCLE_DOT):
                self.orbit = OrbitPanel(gui, feed)
        with tabs.add_tab("Alarms", viser.Icon.ALERT_TRIANGLE):
            self.alarms = AlarmsPanel(gui, ctx, feed)
        with tabs.add_tab("Status", viser.Icon.HEART_RATE_MONITOR):
            self.status = StatusPanel(gui, ctx)
        with tabs.add_tab("View", viser.Icon.SETTINGS):
            labels = {u: self.spectra.unit_label(u) for u in range(1, feed.gamma + 1)}
            self.view_tab = SettingsPanel(gui, settings, labels, self.spectra.show_units)
        self.versions: dict[str, int] = {}
        self.drawn: Any = None  # (estimate, mean state) drawn last
        self.last_spectra = -math.inf

    def remove(self) -> None:
        self.scene.remove()
        self.tabs.remove()

    def changed(self, what: str, version: int) -> bool:
        if self.versions.get(what) == version:
            return False
        self.versions[what] = version
        return True


class ClientView:
    """The GUI and scene of one connected browser, updated by the dashboard's render thread."""

    def __init__(self, ctx: ViewContext, client: viser.ClientHandle) -> None:
        self.ctx = ctx
        self.client = client
        self.closed = False
        self.settings = ViewSettings()
        self.shown: _Shown | None = None
        self._camera: tuple | None = None  # a camera to set once the browser's is known
        self._last_text = -math.inf
        with client.atomic():
            self.controls = ControlsPanel(client.gui, ctx, self.settings)
            self.controls.header.content = header_html(self._header_info(), None, None)

    @property
    def feed(self) -> "StructureFeed | None":
        return None if self.shown is None else self.shown.feed

    @property
    def paused(self) -> bool:
        return self.settings.paused

    def show(self, feed: "StructureFeed") -> None:
        """Draw ``feed``'s structure: its rig, beam and sensors, and its spectra, trends, loads,
        alarms, status and view settings (a switch removes the previous structure's first)."""
        with self.client.atomic():
            if self.shown is not None:
                self.shown.remove()
            s = self.settings
            s.units_shown = set(range(1, feed.gamma + 1))
            s.rigid_scale = 1.0
            s.dirty_scene = s.dirty_trends = s.dirty_spectra = True
            self.shown = _Shown(self.client, self.ctx, feed, s)
            self._camera = camera_of(feed)
            self._place_camera()

    def _place_camera(self) -> None:
        """Frame the structure shown (once the browser has told viser its camera)."""
        if self._camera is None:
            return
        try:
            self.client.camera.position, self.client.camera.look_at = self._camera
        except AssertionError:  # viser: this browser's camera is not known yet; try again next frame
            return
        self._camera = None

    def sync_selection(self) -> None:
        """(render thread) Switch to the chosen structure once its feed is ready (keeping the
        poller reading the one shown)."""
        if self.closed:
            return
        self._place_camera()
        wanted = self.controls.choose(self.feed)
        if wanted is None:
            return
        got = self.ctx.structures.feed(wanted)  # also tells the poller the structure is still shown
        if self.feed is not None and self.feed.id == wanted:
            return
        if isinstance(got, str):
            self.controls.loading(got, error=True)
        elif got is None:
            self.controls.loading(f"Loading {wanted}…")
        else:
            self.controls.loading(None)
            self.show(got)

    def _header_info(self) -> HeaderInfo:
        feed = self.feed
        sid = None if feed is None else feed.id
        return HeaderInfo(label=self.ctx.label, fleet=self.ctx.fleet, structure_id=sid,
                          summary=self.ctx.structures.summary(sid), paused=self.settings.paused,
                          clamped=feed is not None and feed.layout.phi is None)

    # ------------------------------------------------------------------ rendering
    def render(self, snap: "Snapshot | None") -> None:
        """Draw what changed (``snap``: the shown structure's; None while there is none yet)."""
        if self.closed:
            return
        now = time.monotonic()
        self.controls.render_overview(None if self.feed is None else self.feed.id)
        texts = now - self._last_text >= TEXT_MIN_PERIOD_S
        if texts:
            self._last_text = now
        shown = self.shown
        if snap is None or shown is None:
            if texts:
                self.controls.header.content = header_html(self._header_info(), None, None)
            return
        with self.client.atomic():
            self._render_scene(shown, snap, texts)
            self._render_plots(shown, snap, now)
            if shown.changed("alarms", snap.alarms_version):
                shown.alarms.render(snap)
            if shown.changed("status", snap.status_version):
                shown.status.render(snap)
            if shown.loads is not None:
                shown.loads.render(snap)
            if texts:
                est = snap.estimate if not self.paused or shown.drawn is None else shown.drawn[0]
                self.controls.header.content = header_html(self._header_info(), snap, est)

    def _render_scene(self, shown: _Shown, snap: "Snapshot", texts: bool) -> None:
        s = self.settings
        if not s.paused and snap.estimate is not None and shown.changed("estimate", snap.estimate_version):
            shown.drawn = (snap.estimate, snap.mean_state)
            s.dirty_scene = True
            if shown.orbit is not None:
                shown.orbit.add(snap.estimate)
        if shown.orbit is not None and not s.paused:
            shown.orbit.render(time.monotonic())
        if self.controls.auto_changed:
            self.controls.auto_changed = False
            shown.scene.reset_envelope()
        if not s.dirty_scene or shown.drawn is None:
            return
        s.dirty_scene = False
        if self.controls.auto_scale.value:
            scale = shown.scene.auto_overscale(shown.drawn[0].state, s.elastic_scale)
            if scale != s.elastic_scale:
                s.elastic_scale = scale
                self.controls.overscale.value = scale
        est, mean = shown.drawn
        shown.scene.render(est, mean, shown.view_tab.options(), texts=s.paused or texts)

    def _render_plots(self, shown: _Shown, snap: "Snapshot", now: float) -> None:
        s = self.settings
        spectra_new = snap.spectra is not None and (shown.versions.get("spectra") != snap.spectra_version or s.dirty_spectra)
        if not s.paused and spectra_new and now - shown.last_spectra >= SPECTRA_MIN_PERIOD_S:
            shown.versions["spectra"] = snap.spectra_version
            shown.last_spectra, s.dirty_spectra = now, False
            shown.spectra.render(snap, s.units_shown)
        if shown.feed.thresholds(snap) != shown.trends.drawn_thresholds:  # the service's levels arrived or changed
            s.dirty_trends = True
        fresh = shown.versions.get("windows") != snap.windows_version
        if (not s.paused and fresh) or (s.dirty_trends and snap.windows):
            shown.versions["windows"] = snap.windows_version
            s.dirty_trends = False
            shown.trends.render(snap, s)
