"""One browser's view: its live scene nodes and its GUI (controls, spectra, trends, alarms, status)."""

from __future__ import annotations

import datetime as _dt
import html
import logging
import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from contract import AlarmDocument, StatusDocument

from ._data import WindowRecord, frequencies_of, spectrum_plot
from ._fleet import overview_html
from ._geometry import (
    BeamState,
    centreline,
    clamp_boxes,
    ribbon,
    ribbon_faces,
    segments,
    to_world,
    tof_rays,
    up_sign,
)

if TYPE_CHECKING:
    from ._dashboard import Dashboard
    from ._feed import Snapshot, StructureFeed

log = logging.getLogger(__name__)

#: Sensor marker colours by state (RGB).
STATE_COLOURS = {
    "ok": (40, 167, 69),
    "degraded": (255, 170, 0),
    "rejected": (220, 38, 38),
    "unknown": (140, 140, 140),
}
MODE_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
BEAM_COLOUR = (30, 100, 200)
GHOST_COLOUR = (150, 150, 150)
TRUTH_COLOUR = (235, 120, 20)
CLAMP_COLOUR = (70, 74, 84)
N_BEAM_POINTS = 121
TREND_WINDOWS = {"10 min": 600.0, "1 h": 3600.0, "6 h": 6 * 3600.0, "24 h": 86400.0, "7 days": 7 * 86400.0, "all": math.inf}
SPECTRA_MIN_PERIOD_S = 0.5
MAX_OVERSCALE = 500.0
AUTO_TARGET_FRACTION = 0.1  # auto overscale: largest drawn elastic deflection ≈ 10 % of L
AUTO_DECAY_PER_FRAME = 0.995  # envelope of |Δ| forgets over ~10 s at 20 frames/s
TEXT_MIN_PERIOD_S = 0.25
ALARM_ROWS = 30
#: uPlot draws NaN as missing points (canvas ignores non-finite coordinates).
NAN = float("nan")


class _Tracked:
    """A scene whose ``add_*`` calls record the handles made (a structure's nodes, removed on a switch)."""

    def __init__(self, scene: Any, nodes: list[Any]) -> None:
        self._scene = scene
        self._nodes = nodes

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._scene, name)
        if not name.startswith("add_"):
            return attr

        def add(*args: Any, **kwargs: Any) -> Any:
            handle = attr(*args, **kwargs)
            self._nodes.append(handle)
            return handle

        return add


def camera_of(feed: "StructureFeed") -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(position, look-at) of a front view of the beam's plane (ζ to the right, z up: −η hanging,
    +η standing), slightly from the side; the look-at point sits right of the beam so the beam is
    not hidden behind the GUI panel."""
    L, up = feed.length, up_sign(feed.standing)
    refl = 0.0 if feed.reflector_distance is None else feed.reflector_distance
    look_x = 0.55 + 0.6 * refl
    return (look_x + 0.9, -0.95 * L, up * 0.40 * L), (look_x, 0.0, up * 0.5 * L)


def add_rig(scene: Any, feed: "StructureFeed") -> None:
    """The rig's static parts: the rail the support runs on (above D for a hanging beam, below a
    standing mast), the reflector, a grid in the beam's plane and the plumb line."""
    L, has_reflector = feed.length, feed.reflector_distance is not None
    refl = feed.reflector_distance if has_reflector else 0.0  # no ToFs: no reflector to draw
    up = up_sign(feed.standing)  # world z per unit η: the beam hangs down or stands up from D
    rail_lo, rail_hi = min(-0.6, refl - 1.2), refl + 0.05
    scene.add_box(
        "/rig/rail", color=(90, 90, 100), dimensions=(rail_hi - rail_lo, 0.08, 0.04),
        position=(0.5 * (rail_lo + rail_hi), 0.0, -up * 0.09), cast_shadow=False,
    )
    scene.add_label("/rig/rail_label", "bearing rail", position=(rail_lo, 0.0, -up * 0.16), font_screen_scale=0.8)
    if has_reflector:
        scene.add_box(
            "/rig/reflector", color=(150, 175, 205), dimensions=(0.01, 0.9, L + 0.4),
            position=(refl + 0.005, 0.0, up * 0.5 * L), opacity=0.35, side="double", cast_shadow=False,
        )
        scene.add_label("/rig/reflector_label", f"reflector ζ = {refl:g} m", position=(refl, 0.45, -up * 0.1),
                        font_screen_scale=0.8)
    scene.add_grid(
        "/rig/grid", width=max(2.0, 2 * refl + 1.5), height=L + 1.0, plane="xz",
        cell_size=0.1, section_size=0.5, position=(0.5 * refl, 0.45, up * 0.5 * L), shadow_opacity=0.0,
    )
    scene.add_line_segments(
        "/rig/plumb", np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, up * L]]]), (160, 160, 160), thickness=0.004,
    )


def fmt_time(t: float | None) -> str:
    """UNIX seconds as UTC clock time; small values (seconds since the start) as seconds."""
    if t is None or not math.isfinite(t):
        return "–"
    if t > 1e9:
        return _dt.datetime.fromtimestamp(t, tz=_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    return f"{t:.1f} s"


def _fmt(v: Any, fmt: str = "{:.3g}", none: str = "–") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
        return fmt.format(v)
    return html.escape(str(v))


def _arr(values: list[float | None]) -> np.ndarray:
    return np.array([NAN if v is None else v for v in values], dtype=float)


class ClientView:
    """Scene nodes and GUI of one connected browser, updated by the dashboard's render thread."""

    # ------------------------------------------------------------------ shared (all clients)
    @staticmethod
    def setup_shared(dash: "Dashboard") -> None:
        server = dash.server
        server.gui.configure_theme(
            control_width="large", show_logo=False, show_share_button=False, brand_color=(30, 100, 200)
        )
        server.scene.set_up_direction("+z")
        # Shadows and the HDR environment cost a software-rendered browser (no GPU) 10× its frame
        # rate, and a hanging sheet needs neither: plain default lights.
        server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        server.scene.configure_environment_map(None)
        server.scene.add_light_ambient("/lights/ambient", intensity=1.6)
        server.scene.add_light_hemisphere("/lights/sky", sky_color=(255, 255, 255), ground_color=(200, 205, 215), intensity=1.2)
        if dash.primary is not None:  # one structure: its rig is the same for every browser
            server.initial_camera.position, server.initial_camera.look_at = camera_of(dash.primary)
            add_rig(server.scene, dash.primary)

    # ------------------------------------------------------------------ per client
    def __init__(self, dash: "Dashboard", client: viser.ClientHandle, feed: "StructureFeed | None" = None) -> None:
        self.dash = dash
        self.client = client
        self.closed = False
        self.paused = False
        self.elastic_scale = 20.0
        self.feed: StructureFeed | None = None
        self.wanted: str | None = None  # a fleet: the structure chosen (shown once its feed is ready)
        self.tabs: Any = None
        self._nodes: list[Any] = []  # the shown structure's scene nodes (removed on a switch)
        self._overview_version = -1
        self._overview_selected: str | None = None
        self._camera: tuple | None = None  # a camera to set once the browser's is known
        self._last_text = -math.inf
        with client.atomic():
            self._build_controls()
        if feed is not None:
            self.show(feed)

    def show(self, feed: "StructureFeed") -> None:
        """Draw ``feed``'s structure: its rig, beam and sensors, and its spectra, trends, alarms,
        status and view settings (a switch removes the previous structure's first)."""
        with self.client.atomic():
            for node in self._nodes:
                node.remove()
            self._nodes = []
            if self.tabs is not None:
                self.tabs.remove()
            self.feed = feed
            self.rigid_scale = 1.0
            self.units_shown = set(range(1, feed.gamma + 1))  # unit deformations (and their modes) shown
            self.trend_window_s = TREND_WINDOWS["1 h"]
            self.dirty_scene = True
            self.dirty_trends = True
            self._drawn_estimate: Any = None
            self._est_version = -1
            self._spec_version = -1
            self._win_version = -1
            self._alarm_version = -1
            self._status_version = -1
            self._last_spectra = -math.inf
            self._last_text = -math.inf
            self._time_axis: bool | None = None
            self._drawn_thresholds: dict[str, tuple[float, float]] | None = None
            self._envelope = 0.0
            self._eta = np.linspace(0.0, feed.length, N_BEAM_POINTS)
            self._faces = ribbon_faces(N_BEAM_POINTS)
            self._widths = feed.width_at(self._eta)  # to scale: a tube's diameter, a sheet's width
            self._shape_eta = np.asarray(feed.units.shape(self._eta), dtype=float)
            scene = _Tracked(self.client.scene, self._nodes)
            if self.dash.fleet:  # each browser its own structure: its rig and camera
                add_rig(scene, feed)
                self._camera = camera_of(feed)
                self._place_camera()
            self._build_scene_groups()
            self._build_scene(scene)
            self._build_tabs()

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
        """A fleet (render thread): keep the selector's options current and switch to the chosen
        structure once its feed is ready (keeping the poller reading the one shown)."""
        poller = self.dash.poller
        if poller is None or self.closed:
            return
        self._place_camera()
        ids = tuple(poller.ids())
        if ids and tuple(self.selector.options) != ids:
            current = self.wanted
            self.selector.options = ids
            if current in ids:
                self.selector.value = current
        if self.wanted is None and ids:
            first = next((s.id for s in sorted(poller.overview.structures, key=lambda s: s.state == "failed")), ids[0])
            self.wanted = first
            self.selector.value = first
        if self.wanted is None:
            return
        if self.feed is not None and self.feed.id == self.wanted:
            poller.feed(self.wanted)  # still shown: keep it read
            return
        got = poller.feed(self.wanted)
        if isinstance(got, str):
            self.select_info.content = f"<p style='color:#dc2626;font-size:12px'>{html.escape(got)}</p>"
        elif got is None:
            self.select_info.content = f"<p style='font-size:12px'>Loading {html.escape(self.wanted)}…</p>"
        else:
            self.select_info.content = ""
            self.show(got)

    def _build_scene_groups(self) -> None:
        """Sensors on the beam, by kind, and one label per board/gauge name."""
        groups: dict[str, list[tuple[str, float]]] = {"imu": [], "tof": [], "strain": []}
        for topic, sensor in self.feed.sensor_topics.items():
            if sensor.kind in groups:
                groups[sensor.kind].append((topic, float(sensor.position)))
        self.sensor_groups = {k: v for k, v in groups.items() if v}
        labels: dict[str, float] = {}
        for sensor in self.feed.rig.sensors:
            if sensor.kind in groups and sensor.name not in labels:
                labels[sensor.name] = float(sensor.position)
        self.label_names = list(labels)
        self.label_eta = np.array(list(labels.values()), dtype=float)
        self.bearing_topic = next((t for t, s in self.feed.sensor_topics.items() if s.kind == "bearing"), None)

    def _build_scene(self, scene: Any) -> None:
        rest = BeamState(0.0, 0.0, 0.0, np.zeros(self.feed.gamma))
        up = self.up = up_sign(self.feed.standing)
        verts = ribbon(centreline(rest, self.feed.units, self._eta), self._widths, standing=self.feed.standing)
        self.ghost = scene.add_mesh_simple(
            "/live/ghost", verts, self._faces, color=GHOST_COLOUR, opacity=0.28, side="double", cast_shadow=False
        )
        self.beam = scene.add_mesh_simple(
            "/live/beam", verts, self._faces, color=BEAM_COLOUR, side="double", cast_shadow=False
        )
        self.truth = scene.add_line_segments(
            "/live/truth", segments(to_world(np.zeros((2, 2)))), TRUTH_COLOUR, thickness=0.015, visible=False
        )
        # The support: a pin (the plain bearing, its axis across the sheet) or a clamp (jaws on
        # both faces of the root and the carriage they sit on; φ ≡ 0, so no tangent to show).
        self.bearing = self.tangent = None
        self.clamp: list[Any] = []
        if self.feed.clamped:
            for name, (centre, dims) in zip(("jaw_minus", "jaw_plus", "carriage"),
                                            clamp_boxes(rest, self.feed.width, standing=self.feed.standing)):
                self.clamp.append(scene.add_box(f"/live/clamp/{name}", color=CLAMP_COLOUR, dimensions=dims,
                                                position=centre, cast_shadow=False))
            self.clamp_label = scene.add_label(
                "/live/clamp_label", "clamp (φ ≡ 0)", position=(-0.12, 0.0, -up * 0.05), font_screen_scale=0.8,
                anchor="center-right",
            )
        else:
            self.bearing = scene.add_cylinder(
                "/live/bearing", radius=0.045, height=self.feed.width + 0.12, color=(20, 20, 20),
                wxyz=(math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0), cast_shadow=False,
            )
        self.bearing_marker = scene.add_point_cloud(
            "/live/sensors/bearing", np.zeros((1, 3), dtype=np.float32), np.array([STATE_COLOURS["unknown"]], dtype=np.uint8),
            point_size=0.07, point_shape="circle", precision="float32", point_shading="flat",
            visible=self.bearing_topic is not None,
        )
        if not self.feed.clamped:
            self.tangent = scene.add_line_segments(
                "/live/tangent", np.zeros((1, 2, 3)), (20, 20, 20), thickness=0.006
            )
        self.markers: dict[str, Any] = {}
        shapes = {"imu": ("circle", -0.5 * self.feed.width - 0.03), "tof": ("square", 0.5 * self.feed.width + 0.03), "strain": ("diamond", 0.0)}
        for kind, items in self.sensor_groups.items():
            shape, _ = shapes[kind]
            self.markers[kind] = scene.add_point_cloud(
                f"/live/sensors/{kind}", np.zeros((len(items), 3), dtype=np.float32),
                np.tile(np.array(STATE_COLOURS["unknown"], dtype=np.uint8), (len(items), 1)),
                point_size=0.07, point_shape=shape, precision="float32", point_shading="flat",
            )
        self.marker_offsets = {k: v[1] for k, v in shapes.items()}
        tof = self.sensor_groups.get("tof", [])
        self.rays = None
        if tof:
            self.rays = scene.add_line_segments(
                "/live/tof_rays", np.zeros((len(tof), 2, 3), dtype=np.float32),
                np.tile(np.array((255, 80, 80), dtype=np.uint8), (len(tof), 2, 1)), thickness=0.006,
            )
        self.labels = [
            scene.add_label(f"/live/labels/{i}", name, font_screen_scale=0.75, anchor="center-left")
            for i, name in enumerate(self.label_names)
        ]
        # Beyond the tip: below a hanging beam, above a standing mast.
        self.tip_label = scene.add_label("/live/tip_label", "", font_screen_scale=0.8,
                                         anchor="bottom-center" if self.feed.standing else "top-center")

    # ------------------------------------------------------------------ GUI
    def _build_controls(self) -> None:
        """What does not depend on the structure shown: the header, pause, overscale, and for a
        fleet the structure selector and the overview."""
        gui, dash = self.client.gui, self.dash
        self.header = gui.add_html(self._header_html(None), order=0)
        if dash.fleet:
            with gui.add_folder("Fleet", order=0.5):
                self.selector = gui.add_dropdown(
                    "Structure", ("(waiting for the fleet)",), initial_value="(waiting for the fleet)",
                    hint="The structure this browser shows: its 3-D view, spectra, trends, alarms and status",
                )
                self.select_info = gui.add_html("")
                self.overview_html = gui.add_html("<p style='font-size:12px'>Waiting for the fleet…</p>")

            @self.selector.on_update
            def _(_: Any) -> None:
                value = str(self.selector.value)
                if value in self.dash.poller.ids():
                    self.wanted = value
        self.pause = gui.add_checkbox(
            "Pause live view", False, order=1,
            hint="Freezes this browser's beam, spectra and trends (alarms and status stay live). Never changes data.",
        )
        self.overscale = gui.add_slider(
            "Overscale (elastic)", 1.0, MAX_OVERSCALE, 1.0, self.elastic_scale, order=2,
            hint="Multiplies the elastic deflection Σ b s(η) drawn, like the paper's Figure 15",
        )
        self.auto_scale = gui.add_checkbox(
            "Auto overscale", True, order=2.5,
            hint=f"Keeps the largest drawn elastic deflection of the last seconds near {AUTO_TARGET_FRACTION:.0%} of the beam length",
        )

        @self.pause.on_update
        def _(_: Any) -> None:
            self.paused = bool(self.pause.value)
            self.dirty_scene = self.dirty_trends = True
            dash.set_view_paused()

        @self.overscale.on_update
        def _(event: Any) -> None:
            self.elastic_scale = float(self.overscale.value)
            if event.client is not None:  # moved by the operator (not by auto overscale)
                self.auto_scale.value = False
            self.dirty_scene = True

        @self.auto_scale.on_update
        def _(_: Any) -> None:
            self._envelope = 0.0
            self.dirty_scene = True

    def _build_tabs(self) -> None:
        gui = self.client.gui
        tabs = self.tabs = gui.add_tab_group(order=3)
        with tabs.add_tab("Spectra", viser.Icon.WAVE_SINE):
            self._build_spectra(gui)
        with tabs.add_tab("Trends", viser.Icon.CHART_LINE):
            self._build_trends(gui)
        with tabs.add_tab("Alarms", viser.Icon.ALERT_TRIANGLE):
            self._build_alarms(gui)
        with tabs.add_tab("Status", viser.Icon.HEART_RATE_MONITOR):
            self.status_html = gui.add_html("<p>Waiting for the service status…</p>")
        with tabs.add_tab("View", viser.Icon.SETTINGS):
            self._build_settings(gui)

    def _unit_label(self, unit: int) -> str:
        """``b1 · mode 1+2 (0.30, 0.86 Hz model)``: the spectra's and the mode switches' label."""
        label = self.feed.mode_map.unit_label(unit)
        freqs = self._model_freqs(unit)
        return f"{label} ({', '.join(f'{f:.2f}' for f in freqs)} Hz model)" if freqs else label

    def _model_freqs(self, unit: int) -> tuple[float, ...]:
        try:
            return tuple(float(f) for f in self.feed.units.frequencies_hz[unit - 1])
        except (AttributeError, IndexError, TypeError, ValueError):
            return ()

    def _model_hz(self, unit: int) -> float | None:
        freqs = self._model_freqs(unit)
        return freqs[-1] if freqs else None

    def _f_max(self) -> float:
        freqs = [self._model_hz(u) for u in range(1, self.feed.gamma + 1)]
        freqs = [f for f in freqs if f]
        return 1.4 * max(freqs) if freqs else 10.0

    def _modes_shown(self) -> list[int]:
        """The eigenmodes of the unit deformations shown."""
        mm = self.feed.mode_map
        return [m for m in mm.modes if mm.unit_of(m) in self.units_shown]

    def _build_spectra(self, gui: Any) -> None:
        gui.add_markdown(
            "Amplitude spectra of the deformation variables b<sub>χ</sub> (latest window, µm, log scale). "
            "Solid spike: tracked eigenfrequency; dashed spike: baseline."
        )
        self.spectra_plots = {}
        f_max = self._f_max()
        f = np.linspace(0.0, f_max, 200)
        for unit in range(1, self.feed.gamma + 1):
            x, y, tr, bl = spectrum_plot(f, np.ones(f.size), None, self._model_freqs(unit))
            self.spectra_plots[unit] = gui.add_uplot(
                data=(x, y, tr, bl),
                series=self._spectrum_series(unit, None, self._model_freqs(unit)),
                scales={"x": {"time": False}, "y": {"distr": 3}},
                title=self._unit_label(unit),
                height=150,
                padding=(12, 16, 0, 0),
                axes=({"ticks": {"show": False}}, {"size": 52, "ticks": {"show": False}}),
                legend={"show": True, "live": False},
            )

    def _spectrum_series(self, unit: int, tracked: object, baseline: object) -> tuple:
        colour = MODE_COLOURS[(unit - 1) % len(MODE_COLOURS)]

        def label(values: object) -> str:
            fs = frequencies_of(values)
            return " / ".join(f"{f:.3f}" for f in fs) if fs else "–"

        return (
            {"label": "Hz"},
            {"label": f"|b{unit}| µm", "stroke": colour, "width": 1.5, "fill": colour + "22"},
            {"label": f"tracked {label(tracked)} Hz", "stroke": "#111111", "width": 1.5, "points": {"show": False}},
            {"label": f"baseline {label(baseline)} Hz", "stroke": "#2e8b57", "width": 1.5, "dash": (5, 4), "points": {"show": False}},
        )

    def _build_trends(self, gui: Any) -> None:
        self.trend_info = gui.add_html("<p>Waiting for the first analysis window…</p>")
        self.freq_plots = {}
        mm = self.feed.mode_map
        modes = mm.modes
        x0 = np.array([0.0, 1.0])
        z = np.zeros(2)
        for mode in modes:
            colour = _colour(mode)
            self.freq_plots[mode] = gui.add_uplot(
                data=(x0, z, z, z, z),
                series=(
                    {"label": "time"},
                    {"label": f"f{mode} Hz", "stroke": colour, "width": 2, "points": {"show": True, "size": 4}},
                    {"label": "expected", "stroke": "#2e8b57", "width": 1, "dash": (6, 4)},
                    {"label": "band −", "stroke": "rgba(46,139,87,0.4)", "width": 1},
                    {"label": "band +", "stroke": "rgba(46,139,87,0.4)", "width": 1},
                ),
                bands=({"series": (4, 3), "fill": "rgba(46,139,87,0.15)"},),
                scales={"x": {"time": False}},
                title=f"{mm.mode_label(mode)} eigenfrequency (Hz) with baseline band",
                height=140, visible=False, legend={"live": False},
            )
        self.damping_plot = gui.add_uplot(
            data=(x0,) + (z,) * len(modes),
            series=({"label": "time"},) + tuple(
                {"label": f"ζ {mm.mode_label(m)} %", "stroke": _colour(m), "width": 1.5, "points": {"show": True, "size": 4}}
                for m in modes
            ),
            scales={"x": {"time": False}}, title="Damping ratio (%)", height=150, visible=False, legend={"live": False},
        )
        self.score_plot = gui.add_uplot(
            data=(x0,) + (z,) * (len(modes) + 4),
            series=({"label": "time"},) + tuple(
                {"label": f"{mm.mode_label(m)} σ", "stroke": _colour(m), "width": 1.5} for m in modes
            ) + _threshold_series(),
            scales={"x": {"time": False}}, title="Frequency control charts: EWMA score (σ) and alarm thresholds",
            height=170, visible=False, legend={"live": False},
        )
        self.temperature_plot = gui.add_uplot(
            data=(x0, z),
            series=({"label": "time"}, {"label": "T °C", "stroke": "#b45309", "width": 1.5}),
            scales={"x": {"time": False}}, title="Temperature (°C)", height=120, visible=False, legend={"live": False},
        )
        st = self.feed.stations
        self.curv_profile_plot = gui.add_uplot(
            data=(st, np.zeros(st.size), np.zeros(st.size)),
            series=(
                {"label": "η m"},
                {"label": "latest", "stroke": "#7c3aed", "width": 2, "points": {"show": True, "size": 5}},
                {"label": "max in range", "stroke": "#a78bfa", "width": 1, "dash": (4, 3)},
            ),
            scales={"x": {"time": False}}, title="Curvature-change index along the beam (η from the bearing, m)",
            height=150, visible=False, legend={"live": False},
        )
        self.curv_trend_plot = gui.add_uplot(
            data=(x0, z),
            series=({"label": "time"}, {"label": "index (RMS)", "stroke": "#7c3aed", "width": 1.5, "points": {"show": True, "size": 4}}),
            scales={"x": {"time": False}}, title="Curvature-change index over time", height=120, visible=False, legend={"live": False},
        )
        self.curv_score_plot = gui.add_uplot(
            data=(x0, z, z, z, z, z),
            series=({"label": "time"}, {"label": "curvature σ", "stroke": "#7c3aed", "width": 1.5}) + _threshold_series(),
            scales={"x": {"time": False}}, title="Curvature control chart: score (σ) and alarm thresholds", height=140,
            visible=False, legend={"live": False},
        )

    def _build_alarms(self, gui: Any) -> None:
        self._alarm_options: dict[str, int] = {}  # dropdown label -> alarm id
        self.alarm_html = gui.add_html("<p>No alarms.</p>")
        self.alarm_choice = gui.add_dropdown("Alarm", ("(none)",), initial_value="(none)")
        self.token = gui.add_text("Operator token", "", hint="Required to acknowledge (same rules as the HTTP API)")
        self.ack_button = gui.add_button("Acknowledge", icon=viser.Icon.CHECK, color="red")
        self.ack_result = gui.add_html("")

        @self.ack_button.on_click
        def _(_: Any) -> None:
            self._acknowledge()

    def _acknowledge(self) -> None:
        alarm_id = self._alarm_options.get(str(self.alarm_choice.value))
        if alarm_id is None:
            self.ack_result.content = "<p style='color:#b45309'>Choose an alarm first.</p>"
            return
        token = str(self.token.value)
        try:
            result = self.dash.service.acknowledge(alarm_id, token, by="dashboard")
        except PermissionError as exc:
            self.ack_result.content = f"<p style='color:#dc2626'>Not acknowledged: {html.escape(str(exc) or 'token missing or wrong')}</p>"
            return
        except KeyError:
            self.ack_result.content = f"<p style='color:#dc2626'>Alarm #{alarm_id} does not exist.</p>"
            return
        except Exception as exc:
            log.exception("acknowledge(%s) failed", alarm_id)
            self.ack_result.content = f"<p style='color:#dc2626'>Acknowledge failed: {html.escape(type(exc).__name__)}: {html.escape(str(exc))}</p>"
            return
        if isinstance(result, AlarmDocument):
            self.feed.push_alarm(result)
        self.ack_result.content = f"<p style='color:#15803d'>Alarm #{alarm_id} acknowledged.</p>"

    def _build_settings(self, gui: Any) -> None:
        self.rigid = gui.add_slider(
            "Overscale (rigid d, h, φ)", 1.0, 50.0, 1.0, 1.0, hint="Multiplies the bearing motion and the attitude drawn"
        )
        self.show_ghost = gui.add_checkbox("Show baseline ghost", True)
        self.ghost_mode = gui.add_dropdown(
            "Ghost shape", ("rest (undeformed)", "running mean (60 s)"), initial_value="rest (undeformed)"
        )
        self.show_truth = gui.add_checkbox("Show truth shape (simulation)", True)
        self.show_rays = gui.add_checkbox("Show ToF rays", True)
        self.show_labels = gui.add_checkbox("Show sensor labels", True)
        gui.add_markdown("**Modes shown** (spectra and trends)")
        self.unit_boxes = {u: gui.add_checkbox(self._unit_label(u), True) for u in range(1, self.feed.gamma + 1)}
        self.trend_window = gui.add_dropdown("Trend window", tuple(TREND_WINDOWS), initial_value="1 h")
        gui.add_markdown(
            "Marker colours: <span style='color:#28a745'>●</span> ok, <span style='color:#ffaa00'>●</span> degraded, "
            "<span style='color:#dc2626'>●</span> rejected samples. Circles: IMUs, squares: ToFs, diamonds: strain gauges."
        )

        def scene_changed(_: Any) -> None:
            self.rigid_scale = float(self.rigid.value)
            self.dirty_scene = True

        for handle in (self.rigid, self.show_ghost, self.ghost_mode, self.show_truth, self.show_rays, self.show_labels):
            handle.on_update(scene_changed)

        def modes_changed(_: Any) -> None:
            self.units_shown = {u for u, box in self.unit_boxes.items() if box.value}
            self.trend_window_s = TREND_WINDOWS.get(str(self.trend_window.value), math.inf)
            for m, plot in self.spectra_plots.items():
                plot.visible = m in self.units_shown
            self.dirty_trends = True
            self._spec_version = -1

        for handle in (*self.unit_boxes.values(), self.trend_window):
            handle.on_update(modes_changed)

    # ------------------------------------------------------------------ rendering
    def render(self, snap: "Snapshot | None") -> None:
        """Draw what changed (``snap``: the shown structure's; None while a fleet's browser has none yet)."""
        if self.closed:
            return
        now = time.monotonic()
        if self.dash.fleet:
            self._render_overview()
        if snap is None or self.feed is None:
            if now - self._last_text >= TEXT_MIN_PERIOD_S:
                self._last_text = now
                self.header.content = self._header_html(None)
            return
        with self.client.atomic():
            if not self.paused and snap.estimate is not None and snap.estimate_version != self._est_version:
                self._drawn_estimate = (snap.estimate, snap.mean_state)
                self._est_version = snap.estimate_version
                self.dirty_scene = True
            if self.dirty_scene and self._drawn_estimate is not None:
                self.dirty_scene = False
                self._render_scene(*self._drawn_estimate, texts=self.paused or now - self._last_text >= TEXT_MIN_PERIOD_S)
            if not self.paused and snap.spectra is not None and snap.spectra_version != self._spec_version and now - self._last_spectra >= SPECTRA_MIN_PERIOD_S:
                self._spec_version = snap.spectra_version
                self._last_spectra = now
                self._render_spectra(snap)
            if self.feed.thresholds(snap) != self._drawn_thresholds:  # the service's levels arrived or changed
                self.dirty_trends = True
            if (not self.paused and snap.windows_version != self._win_version) or (self.dirty_trends and snap.windows):
                self._win_version = snap.windows_version
                self.dirty_trends = False
                self._render_trends(snap)
            if snap.alarms_version != self._alarm_version:
                self._alarm_version = snap.alarms_version
                self._render_alarms(snap)
            if snap.status_version != self._status_version:
                self._status_version = snap.status_version
                self._render_status(snap)
            if now - self._last_text >= TEXT_MIN_PERIOD_S:
                self._last_text = now
                self.header.content = self._header_html(snap)

    def _render_overview(self) -> None:
        poller = self.dash.poller
        shown = None if self.feed is None else self.feed.id
        if poller.overview_version != self._overview_version or shown != self._overview_selected:
            self._overview_version, self._overview_selected = poller.overview_version, shown
            self.overview_html.content = overview_html(poller.overview, poller.overview_error, shown)

    def _render_scene(self, est: Any, mean: BeamState | None, *, texts: bool) -> None:
        feed = self.feed
        state: BeamState = est.state
        if self.auto_scale.value:
            self._auto_overscale(state)
        es, rs = self.elastic_scale, self.rigid_scale
        standing, up = feed.standing, self.up
        line = centreline(state, feed.units, self._eta, elastic_scale=es, rigid_scale=rs)
        self.beam.vertices = ribbon(line, self._widths, standing=standing)
        ghost_on = bool(self.show_ghost.value)
        self.ghost.visible = ghost_on
        if ghost_on:
            if str(self.ghost_mode.value).startswith("running") and mean is not None:
                ghost = centreline(mean, feed.units, self._eta, elastic_scale=es, rigid_scale=rs)
            else:
                ghost = centreline(BeamState(0.0, 0.0, 0.0, np.zeros(feed.gamma)), feed.units, self._eta)
            self.ghost.vertices = ribbon(ghost, self._widths, standing=standing)
        truth_on = est.truth_deflection is not None and bool(self.show_truth.value)
        self.truth.visible = truth_on
        if truth_on:
            eta = np.concatenate([[0.0], feed.stations]) if feed.stations[0] > 0 else feed.stations
            delta = np.concatenate([[0.0], est.truth_deflection]) if feed.stations[0] > 0 else est.truth_deflection
            tline = centreline(state, feed.units, eta, elastic_scale=es, rigid_scale=rs, deflection=delta)
            pts = to_world(tline, y=0.5 * feed.width + 0.01, standing=standing)
            self.truth.points = segments(pts)
        d_world = np.array([rs * state.d, 0.0, up * rs * state.h], dtype=np.float32)
        if self.bearing is not None:
            self.bearing.position = tuple(float(v) for v in d_world)
        if self.tangent is not None:
            phi = rs * state.phi
            self.tangent.points = np.array([[d_world, d_world + 1.0 * np.array([math.sin(phi), 0.0, up * math.cos(phi)])]],
                                           dtype=np.float32)
        if self.clamp:
            for handle, (centre, _) in zip(self.clamp, clamp_boxes(state, feed.width, rigid_scale=rs, standing=standing)):
                handle.position = centre
            if texts:
                self.clamp_label.position = (float(d_world[0]) - 0.12, 0.0, float(d_world[2]) - up * 0.05)
        states = est.sensor_states
        if self.bearing_topic is not None:
            self.bearing_marker.points = (d_world + np.array([0.0, 0.0, -up * 0.13], dtype=np.float32))[None, :]
            self.bearing_marker.colors = np.array([STATE_COLOURS.get(states.get(self.bearing_topic, "unknown"), STATE_COLOURS["unknown"])], dtype=np.uint8)
        for kind, items in self.sensor_groups.items():
            eta = np.array([e for _, e in items])
            pos = to_world(centreline(state, feed.units, eta, elastic_scale=es, rigid_scale=rs), y=self.marker_offsets[kind],
                           standing=standing)
            if kind == "strain":  # on the +ζ face
                pos[:, 0] += 0.01
            self.markers[kind].points = pos
            self.markers[kind].colors = np.array(
                [STATE_COLOURS.get(states.get(topic, "unknown"), STATE_COLOURS["unknown"]) for topic, _ in items], dtype=np.uint8
            )
        if self.rays is not None:
            rays_on = bool(self.show_rays.value)
            self.rays.visible = rays_on
            if rays_on:
                items = self.sensor_groups["tof"]
                eta = np.array([e for _, e in items])
                rays = tof_rays(state, feed.units, eta, feed.reflector_distance, elastic_scale=es, rigid_scale=rs,
                                standing=standing)
                rays[:, :, 1] = self.marker_offsets["tof"]
                self.rays.points = rays
                ray_colours = {"ok": (255, 70, 70), "degraded": (255, 170, 0), "rejected": (150, 150, 150)}
                cols = np.array([ray_colours.get(states.get(t, "ok"), (255, 70, 70)) for t, _ in items], dtype=np.uint8)
                self.rays.colors = np.repeat(cols[:, None, :], 2, axis=1)
        labels_on = bool(self.show_labels.value)
        if self.labels and texts:  # HTML labels are costly for the browser: at the text rate
            pos = to_world(centreline(state, feed.units, self.label_eta, elastic_scale=es, rigid_scale=rs),
                           y=0.5 * feed.width + 0.1, standing=standing)
            for handle, p in zip(self.labels, pos):
                handle.visible = labels_on
                if labels_on:
                    handle.position = (float(p[0]), float(p[1]), float(p[2]))
        tip = line[-1]
        if texts:
            self.tip_label.position = (float(tip[1]), 0.0, float(up * (tip[0] + 0.08)))
            delta_tip = float(feed.units.shape(np.array([feed.length]))[0] @ state.b)
            self.tip_label.text = f"tip Δ = {1e3 * delta_tip:+.1f} mm  (×{es:g})"

    def _auto_overscale(self, state: BeamState) -> None:
        peak = float(np.max(np.abs(self._shape_eta @ state.b)))
        self._envelope = max(peak, self._envelope * AUTO_DECAY_PER_FRAME)
        if self._envelope <= 0:
            return
        wanted = AUTO_TARGET_FRACTION * self.feed.length / self._envelope
        drawn = self.elastic_scale * self._envelope / (AUTO_TARGET_FRACTION * self.feed.length)
        if 0.4 <= drawn <= 1.6:  # hysteresis: keep a steady factor while the picture is readable
            return
        nice = _nice(min(max(wanted, 1.0), MAX_OVERSCALE))
        if nice != self.elastic_scale:
            self.elastic_scale = nice
            self.overscale.value = nice

    def _render_spectra(self, snap: "Snapshot") -> None:
        spec = snap.spectra
        f_max = max(self._f_max(), 1.2 * max([f for fs in (*spec.tracked_hz, *spec.baseline_hz) for f in fs] or [0.0]))
        for unit, plot in self.spectra_plots.items():
            if unit not in self.units_shown:
                continue
            tracked, baseline = spec.tracked_hz[unit - 1], spec.baseline_hz[unit - 1]
            plot.data = spectrum_plot(spec.frequencies_hz, 1e6 * spec.amplitudes[:, unit - 1], tracked, baseline, f_max=f_max)
            series = self._spectrum_series(unit, tracked, baseline)
            if plot.series != series:
                plot.series = series

    def _x(self, times: np.ndarray, plots: list[Any]) -> np.ndarray:
        """Trend x: UNIX seconds on a date axis; seconds since start on a plain axis."""
        time_axis = bool(times.size and times[-1] > 1e9)
        if time_axis != self._time_axis:
            self._time_axis = time_axis
            for p in plots:
                p.scales = {"x": {"time": time_axis}}
        return times

    def _render_trends(self, snap: "Snapshot") -> None:
        feed = self.feed
        windows = snap.windows
        if not windows:
            return
        t_end = windows[-1].t_s
        shown = [w for w in windows if w.t_s >= t_end - self.trend_window_s]
        if len(shown) > 2000:  # keep the browser fast: thin evenly
            shown = shown[:: math.ceil(len(shown) / 2000)]
        trend_plots = [*self.freq_plots.values(), self.damping_plot, self.score_plot, self.temperature_plot,
                       self.curv_trend_plot, self.curv_score_plot]
        x = self._x(np.array([w.t_s for w in shown]), trend_plots)
        if x.size == 1:  # uPlot needs two x values to draw a range
            x = np.array([x[0] - 1.0, x[0]])
            shown = [shown[0], shown[0]]
        visible_modes = set(self._modes_shown())
        for mode, plot in self.freq_plots.items():
            visible = mode in visible_modes
            plot.visible = visible
            if not visible:
                continue
            f = _arr([w.frequency_hz.get(mode) for w in shown])
            bands = [feed.band(snap, w, mode) for w in shown]
            plot.data = (x, f, _arr([b[0] for b in bands]), _arr([b[1] for b in bands]), _arr([b[2] for b in bands]))
        modes = feed.mode_map.modes
        damping = [_arr([None if w.damping_ratio.get(m) is None else 100 * w.damping_ratio[m] for w in shown]) for m in modes]
        self.damping_plot.data = (x, *damping)
        self.damping_plot.visible = any(np.isfinite(d).any() for d in damping)
        th = self._drawn_thresholds = feed.thresholds(snap)
        scores = [_arr([w.score_sigma.get(m) for w in shown]) for m in modes]
        self.score_plot.data = (x, *scores, *_threshold_lines(th.get("frequency"), x.size))
        self.score_plot.visible = any(np.isfinite(s).any() for s in scores)
        for plot, levels in ((self.damping_plot, None), (self.score_plot, th.get("frequency"))):
            series = list(plot.series)
            for i, m in enumerate(modes, start=1):
                if series[i].get("show", True) != (m in visible_modes):
                    series[i] = {**series[i], "show": m in visible_modes}
            if plot is self.score_plot:
                series[len(modes) + 1:] = _threshold_series(levels)
            if tuple(series) != tuple(plot.series):
                plot.series = tuple(series)
        temps = _arr([w.temperature_c for w in shown])
        self.temperature_plot.data = (x, temps)
        self.temperature_plot.visible = bool(np.isfinite(temps).any())
        totals = _arr([w.curvature_total for w in shown])
        self.curv_trend_plot.data = (x, totals)
        self.curv_trend_plot.visible = bool(np.isfinite(totals).any())
        curv_scores = _arr([w.curvature_score_sigma for w in shown])
        self.curv_score_plot.data = (x, curv_scores, *_threshold_lines(th.get("curvature"), x.size))
        self.curv_score_plot.visible = bool(np.isfinite(curv_scores).any())
        curv_series = (*self.curv_score_plot.series[:2], *_threshold_series(th.get("curvature")))
        if tuple(self.curv_score_plot.series) != curv_series:
            self.curv_score_plot.series = curv_series
        profiles = [w.curvature_profile for w in shown if w.curvature_profile is not None]
        if profiles:
            stack = np.array(profiles)
            self.curv_profile_plot.data = (feed.stations, profiles[-1], np.nanmax(stack, axis=0))
            self.curv_profile_plot.visible = True
        self.trend_info.content = self._trend_info_html(windows[-1], len(windows))

    def _trend_info_html(self, w: WindowRecord, count: int) -> str:
        mm = self.feed.mode_map
        cells = []
        for m in mm.modes:
            if m not in w.frequency_hz:
                continue
            cells.append(
                f"<tr><td>{html.escape(mm.mode_label(m))}</td><td>{_fmt(w.frequency_hz.get(m), '{:.4f}')}</td>"
                f"<td>{_fmt(None if w.damping_ratio.get(m) is None else 100 * w.damping_ratio[m], '{:.2f}')}</td>"
                f"<td>{_fmt(w.score_sigma.get(m), '{:+.1f}')}</td><td>{_level_badge(w.level.get(m))}</td></tr>"
            )
        where = ""
        if w.curvature_eta_m is not None:
            where = f" — largest change at η = {w.curvature_eta_m:.2f} m ({html.escape(w.curvature_third or '')} third)"
        return (
            f"<div style='font-size:12px'><b>Latest window</b> {fmt_time(w.start_s)} → {fmt_time(w.end_s)} "
            f"({html.escape(w.kind or '–')}{'' if w.trusted is None else (', trusted' if w.trusted else ', untrusted')}), "
            f"T = {_fmt(w.temperature_c, '{:.1f}')} °C, {count} windows stored."
            f"<table style='width:100%;font-size:12px'><tr><th>mode</th><th>f Hz</th><th>ζ %</th><th>score σ</th><th>chart</th></tr>"
            + "".join(cells)
            + f"</table>Curvature-change index {_fmt(w.curvature_total, '{:.3g}')}"
            f" (score {_fmt(w.curvature_score_sigma, '{:+.1f}')} σ, {_level_badge(w.curvature_level)}){where}</div>"
        )

    def _alarm_label(self, a: AlarmDocument) -> str:
        mm = self.feed.mode_map
        if a.kind == "frequency" and a.mode is not None and a.mode in mm.modes:
            return mm.mode_label(a.mode)
        return a.chart

    def _render_alarms(self, snap: "Snapshot") -> None:
        alarms = snap.alarms
        if not alarms:
            self.alarm_html.content = "<p>No alarms.</p>"
        else:
            rows = []
            for a in alarms[:ALARM_ROWS]:
                state = "active" if a.active else "cleared"
                if a.acknowledged:
                    by = f" by {a.acknowledged_by}" if a.acknowledged_by else ""
                    state += f", acknowledged{by} {fmt_time(a.acknowledged_at_s)}"
                rows.append(
                    f"<tr style='{_alarm_style(a)}'><td>#{a.id}</td><td>{_level_badge(a.level)}</td>"
                    f"<td>{html.escape(self._alarm_label(a))}</td><td>{html.escape(state)}</td><td>{fmt_time(a.raised_at_s)}</td>"
                    f"<td>{html.escape(a.message)}</td></tr>"
                )
            active = sum(1 for a in alarms if a.active)
            self.alarm_html.content = (
                f"<div style='font-size:12px'><b>{active} active</b>, {len(alarms)} in the list."
                "<table style='width:100%;font-size:12px;border-collapse:collapse'>"
                "<tr><th>id</th><th>level</th><th>chart</th><th>state</th><th>since</th><th>message</th></tr>"
                + "".join(rows) + "</table></div>"
            )
        self._alarm_options = {f"#{a.id} {a.level} {self._alarm_label(a)}": a.id for a in alarms if not a.acknowledged}
        options = tuple(self._alarm_options) or ("(none)",)
        if tuple(self.alarm_choice.options) != options:
            current = self.alarm_choice.value
            self.alarm_choice.options = options
            if current in options:
                self.alarm_choice.value = current

    def _render_status(self, snap: "Snapshot") -> None:
        self.status_html.content = _status_html(snap, self.dash)

    def _title(self) -> str:
        """The label; for a fleet, the structure shown with its state and lag (as the overview lists it)."""
        title = f"<b>{html.escape(self.dash.label)}</b>"
        if not self.dash.fleet or self.feed is None:
            return title
        summary = self.dash.poller.summary(self.feed.id)
        extra = ""
        if summary is not None:
            lag = "" if summary.lag_s is None else f", lag {summary.lag_s:.1f} s"
            extra = f" ({html.escape(summary.state)}{lag})"
        return f"{title}<br><b style='font-size:14px'>Structure {html.escape(str(self.feed.id))}</b>{extra}"

    def _header_html(self, snap: "Snapshot | None") -> str:
        dash = self.dash
        if snap is None:
            waiting = "Choose a structure (loading the fleet…)" if dash.fleet else "Connecting to the data…"
            return f"<div style='font-size:13px'>{self._title()}<br>{waiting}</div>"
        live = "<span style='color:#b45309;font-weight:bold'>■ PAUSED</span>" if self.paused else "<span style='color:#15803d;font-weight:bold'>● LIVE</span>"
        est = snap.estimate if not self.paused or self._drawn_estimate is None else self._drawn_estimate[0]
        # what the service is doing now (compiling, calibrating at rest, waiting for the first window, ...)
        progress = None if snap.status is None else getattr(snap.status.service, "progress", None)
        if est is None:
            motion = html.escape(progress) if progress else "waiting for estimates"
            progress = None
        else:
            s = est.state
            phi = "φ ≡ 0 (clamped)" if self.feed.layout.phi is None else f"φ = {1e3 * s.phi:+.2f} mrad"
            motion = (
                f"t = {fmt_time(est.t_s)} · d = {1e3 * s.d:+.1f} mm · {phi} · "
                f"b = [{', '.join(f'{v:+.2e}' for v in s.b)}]"
            )
        active = [a for a in snap.alarms if a.active]
        n_alarm = sum(1 for a in active if a.level == "alarm")
        n_warn = len(active) - n_alarm
        if n_alarm:
            badge = f"<span style='background:#dc2626;color:white;padding:1px 6px;border-radius:4px'>{n_alarm} ALARM</span>"
        elif n_warn:
            badge = f"<span style='background:#ffaa00;color:black;padding:1px 6px;border-radius:4px'>{n_warn} warning</span>"
        else:
            badge = "<span style='background:#15803d;color:white;padding:1px 6px;border-radius:4px'>no active alarms</span>"
        if n_alarm and n_warn:
            badge += f" <span style='background:#ffaa00;color:black;padding:1px 6px;border-radius:4px'>{n_warn} warning</span>"
        degraded = []
        if snap.status is not None:
            degraded = list(snap.status.degraded_sensors)
        elif snap.estimate is not None:
            degraded = [t for t, v in snap.estimate.sensor_states.items() if v != "ok"]
        sensors = (
            f"<span style='color:#b45309'>degraded/rejected: {html.escape(', '.join(degraded))}</span>" if degraded else "all sensors ok"
        )
        error = f"<br><span style='color:#dc2626'>service: {html.escape(snap.status_error)}</span>" if snap.status_error else ""
        return (
            f"<div style='font-size:12.5px;line-height:1.45'>{self._title()} {live} {badge}<br>"
            f"{motion}<br>{_rates(snap)} · {sensors}{error}"
            f"{'' if not progress else '<br><i>' + html.escape(progress) + '</i>'}</div>"
        )


def _rates(snap: "Snapshot") -> str:
    """The estimator's rate (estimates per second of data), its pace against real time and how
    often the picture gets a new state (the pipeline hands on one state per batch, not every one)."""
    drawn = f"drawn {snap.estimate_rate_hz:.0f} Hz"
    if snap.filter_rate_hz is None:
        return f"estimates: waiting for the filter's progress · {drawn}"
    return f"estimates {snap.filter_rate_hz:.0f} Hz · {snap.realtime_factor:.1f}× real time · {drawn}"


def _colour(index: int) -> str:
    return MODE_COLOURS[(index - 1) % len(MODE_COLOURS)]


def _threshold_series(levels: tuple[float, float] | None = None) -> tuple[dict, ...]:
    """The four level lines of a control chart; their legend names the levels (σ) in force."""
    warning, alarm = ("?", "?") if levels is None else (f"{levels[0]:g}", f"{levels[1]:g}")
    return (
        {"label": f"warning +{warning} σ", "stroke": "#ffaa00", "dash": (6, 4), "width": 1},
        {"label": f"warning −{warning} σ", "stroke": "#ffaa00", "dash": (6, 4), "width": 1},
        {"label": f"alarm +{alarm} σ", "stroke": "#dc2626", "dash": (6, 4), "width": 1.5},
        {"label": f"alarm −{alarm} σ", "stroke": "#dc2626", "dash": (6, 4), "width": 1.5},
    )


def _threshold_lines(levels: tuple[float, float] | None, n: int) -> tuple[np.ndarray, ...]:
    """±warning, ±alarm as constant series (NaN, i.e. not drawn, while the levels are unknown)."""
    warning, alarm = levels if levels is not None else (NAN, NAN)
    ones = np.ones(n)
    return warning * ones, -warning * ones, alarm * ones, -alarm * ones


def _nice(x: float) -> float:
    """Round down to 1, 2 or 5 × 10^k (a steady overscale factor that does not flicker)."""
    k = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= x:
            return m * 10**k
    return 10.0**k


def _level_badge(level: str | None) -> str:
    """A chart level's badge; "not charted" for a mode without a chart (no baseline, too few cycles)."""
    if level is None:
        return "<span style='color:#888'>not charted</span>"
    colours = {"alarm": ("#dc2626", "white"), "warning": ("#ffaa00", "black"), "ok": ("#15803d", "white")}
    bg, fg = colours.get(level, ("#888", "white"))
    return f"<span style='background:{bg};color:{fg};padding:0 5px;border-radius:3px'>{html.escape(level)}</span>"


def _alarm_style(a: AlarmDocument) -> str:
    if not a.active:
        return "color:#777"
    return "background:#fee2e2" if a.level == "alarm" else "background:#fef3c7"


def _status_html(snap: "Snapshot", dash: "Dashboard") -> str:
    parts = []
    status: StatusDocument | None = snap.status
    if snap.status_error:
        parts.append(f"<p style='color:#dc2626'>Service status unavailable: {html.escape(snap.status_error)}</p>")
    if status is None:
        parts.append("<p>No status from the service yet.</p>")
    else:
        service = status.service
        error = ""
        if service.pipeline_errors:
            error = (f" · <span style='color:#dc2626'>{service.pipeline_errors} failed batches"
                     f"{', now: ' + html.escape(service.pipeline_error) if service.pipeline_error else ' (recovered)'}</span>")
        parts.append(
            f"<p><b>Service</b> {html.escape(service.version)} · up {_fmt(service.uptime_s, '{:.0f}')} s · "
            f"pushes {'paused' if service.paused else 'live'}{error}</p>"
        )
        if status.sources:
            rows = "".join(
                f"<tr><td>{html.escape(s.id)}</td><td>{html.escape(s.kind)}</td>"
                f"<td>{html.escape(s.state)}</td><td>{_fmt(s.rate_hz, '{:.0f}')}</td>"
                f"<td>{_fmt(s.latency_s, '{:.3f}')}</td><td>{_fmt(s.messages, '{:.0f}')}</td>"
                f"<td>{_fmt(s.dropped, '{:.0f}')}</td><td>{_fmt(s.rejected, '{:.0f}')}</td></tr>"
                for s in status.sources
            )
            parts.append(
                "<table style='width:100%;font-size:12px'><tr><th>source</th><th>kind</th><th>state</th><th>msg/s</th>"
                "<th>latency s</th><th>messages</th><th>dropped</th><th>rejected</th></tr>" + rows + "</table>"
            )
        p = status.pipeline
        parts.append(
            f"<p><b>Pipeline</b> samples {p.samples} · estimates {p.estimates} ({html.escape(p.estimator.state)}) · "
            f"windows {p.windows_committed} committed, {p.windows_skipped_warmup} warm-up, "
            f"{p.windows_skipped_incomplete} incomplete · queue {p.queue_depth}/{p.queue_capacity} · "
            f"latency {_fmt(p.pipeline_latency_s, '{:.3f}')} s · {_fmt(p.realtime_factor, '{:.1f}')}× real time</p>"
        )
        sinks = [f"{html.escape(name)}: {sink.errors} ({html.escape(', '.join(f'{k} {v}' for k, v in sink.errors_by_kind.items()))})"
                 for name, sink in status.sinks.items() if sink.errors]
        if sinks:
            parts.append(f"<p><b>Sink failures</b> <span style='color:#b45309'>{'; '.join(sinks)}</span></p>")
        if status.sensors:
            cells = " ".join(
                f"<span style='color:{_rgb(v)}'>●</span>&nbsp;{html.escape(t)}" for t, v in sorted(status.sensors.items())
            )
            parts.append(f"<p><b>Sensors</b> {cells}</p>")
        th = status.thresholds
        parts.append(
            f"<p><b>Baseline</b> {html.escape(status.baseline.state)} · charts: frequency warning "
            f"{th.frequency.warning_sigma:g} σ, alarm {th.frequency.alarm_sigma:g} σ; curvature warning "
            f"{th.curvature.warning_sigma:g} σ, alarm {th.curvature.alarm_sigma:g} σ</p>"
        )
        st = status.storage
        parts.append(f"<p><b>Storage</b> {html.escape(st.db)} · schema {st.schema_version} · {st.trend_rows} trend rows</p>")
    parts.append(
        f"<p style='color:#666'>Dashboard: {dash.client_count} browser(s), {1 / max(dash.last_frame_s, 1e-3):.0f} frames/s possible "
        f"(last frame {1e3 * dash.last_frame_s:.1f} ms), states arriving at {snap.estimate_rate_hz:.0f} Hz.</p>"
    )
    return "<div style='font-size:12px'>" + "".join(parts) + "</div>"


def _rgb(state: Any) -> str:
    r, g, b = STATE_COLOURS.get(str(state), STATE_COLOURS["unknown"])
    return f"rgb({r},{g},{b})"
