"""One browser's 3-D scene of the structure shown: the rig's static parts, the live beam, its
support, sensors, ToF rays, labels and the truth shape of a simulation."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ._geometry import BeamState, centreline, clamp_boxes, lateral, ribbon, ribbon_faces, segments, to_world, tof_rays, up_sign
from ._html import STATE_COLOURS

if TYPE_CHECKING:
    from ._feed import Estimate, StructureFeed

__all__ = ["SceneOptions", "SceneView", "add_rig", "camera_of", "nice_scale"]

BEAM_COLOUR = (30, 100, 200)
GHOST_COLOUR = (150, 150, 150)
TRUTH_COLOUR = (235, 120, 20)
CLAMP_COLOUR = (70, 74, 84)
N_BEAM_POINTS = 121
MAX_OVERSCALE = 500.0
AUTO_TARGET_FRACTION = 0.1  # auto overscale: largest drawn elastic deflection ≈ 10 % of L
AUTO_DECAY_PER_FRAME = 0.995  # envelope of |Δ| forgets over ~10 s at 20 frames/s
_RAY_COLOURS = {"ok": (255, 70, 70), "degraded": (255, 170, 0), "rejected": (150, 150, 150)}


def nice_scale(x: float) -> float:
    """Round down to 1, 2 or 5 × 10^k (a steady overscale factor that does not flicker)."""
    k = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= x:
            return m * 10**k
    return 10.0**k


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
    has_reflector = feed.reflector_distance is not None
    L, refl = feed.length, float(feed.reflector_distance or 0.0)  # no ToFs: no reflector to draw
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


@dataclass(frozen=True)
class SceneOptions:
    """What the operator chose to see (the View tab) and the scales of the drawing."""

    elastic_scale: float = 20.0
    rigid_scale: float = 1.0
    ghost: bool = True
    running_mean_ghost: bool = False
    truth: bool = True
    rays: bool = True
    labels: bool = True


class SceneView:
    """The scene nodes of one structure in one browser (``remove()`` on a switch)."""

    def __init__(self, client_scene: Any, feed: "StructureFeed") -> None:
        self.feed = feed
        self.nodes: list[Any] = []
        scene = _Tracked(client_scene, self.nodes)
        self.eta = np.linspace(0.0, feed.length, N_BEAM_POINTS)
        self.faces = ribbon_faces(N_BEAM_POINTS)
        self.widths = feed.width_at(self.eta)  # to scale: a tube's diameter, a sheet's width
        self.shape_eta = np.asarray(feed.units.shape(self.eta), dtype=float)
        self.shape_eta_xi = None if feed.units_xi is None else np.asarray(feed.units_xi.shape(self.eta), dtype=float)
        self.up = up_sign(feed.standing)
        self._envelope = 0.0
        add_rig(scene, feed)
        self._group_sensors()
        self._add_beam(scene)
        self._add_support(scene)
        self._add_sensors(scene)

    def remove(self) -> None:
        for node in self.nodes:
            node.remove()
        self.nodes = []

    # ------------------------------------------------------------------ building
    def _group_sensors(self) -> None:
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

    def _rest(self) -> BeamState:
        return BeamState(0.0, 0.0, 0.0, np.zeros(self.feed.gamma))

    def _add_beam(self, scene: Any) -> None:
        verts = ribbon(centreline(self._rest(), self.feed.units, self.eta), self.widths, standing=self.feed.standing)
        self.ghost = scene.add_mesh_simple(
            "/live/ghost", verts, self.faces, color=GHOST_COLOUR, opacity=0.28, side="double", cast_shadow=False
        )
        self.beam = scene.add_mesh_simple("/live/beam", verts, self.faces, color=BEAM_COLOUR, side="double", cast_shadow=False)
        self.truth = scene.add_line_segments(
            "/live/truth", segments(to_world(np.zeros((2, 2)))), TRUTH_COLOUR, thickness=0.015, visible=False
        )
        # Beyond the tip: below a hanging beam, above a standing mast.
        self.tip_label = scene.add_label("/live/tip_label", "", font_screen_scale=0.8,
                                         anchor="bottom-center" if self.feed.standing else "top-center")

    def _add_support(self, scene: Any) -> None:
        """A pin (the plain bearing, its axis across the sheet) or a clamp (jaws on both faces of
        the root and the carriage they sit on; φ ≡ 0, so no tangent to show)."""
        feed, up = self.feed, self.up
        self.bearing = self.tangent = self.clamp_label = None
        self.clamp: list[Any] = []
        if feed.clamped:
            for name, (centre, dims) in zip(("jaw_minus", "jaw_plus", "carriage"),
                                            clamp_boxes(self._rest(), feed.width, standing=feed.standing)):
                self.clamp.append(scene.add_box(f"/live/clamp/{name}", color=CLAMP_COLOUR, dimensions=dims,
                                                position=centre, cast_shadow=False))
            self.clamp_label = scene.add_label("/live/clamp_label", "clamp (φ ≡ 0)", position=(-0.12, 0.0, -up * 0.05),
                                               font_screen_scale=0.8, anchor="center-right")
        else:
            self.bearing = scene.add_cylinder(
                "/live/bearing", radius=0.045, height=feed.width + 0.12, color=(20, 20, 20),
                wxyz=(math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0), cast_shadow=False,
            )
            self.tangent = scene.add_line_segments("/live/tangent", np.zeros((1, 2, 3)), (20, 20, 20), thickness=0.006)
        self.bearing_marker = scene.add_point_cloud(
            "/live/sensors/bearing", np.zeros((1, 3), dtype=np.float32), np.array([STATE_COLOURS["unknown"]], dtype=np.uint8),
            point_size=0.07, point_shape="circle", precision="float32", point_shading="flat",
            visible=self.bearing_topic is not None,
        )

    def _add_sensors(self, scene: Any) -> None:
        width = self.feed.width
        shapes = {"imu": ("circle", -0.5 * width - 0.03), "tof": ("square", 0.5 * width + 0.03), "strain": ("diamond", 0.0)}
        self.markers: dict[str, Any] = {}
        for kind, items in self.sensor_groups.items():
            self.markers[kind] = scene.add_point_cloud(
                f"/live/sensors/{kind}", np.zeros((len(items), 3), dtype=np.float32),
                np.tile(np.array(STATE_COLOURS["unknown"], dtype=np.uint8), (len(items), 1)),
                point_size=0.07, point_shape=shapes[kind][0], precision="float32", point_shading="flat",
            )
        self.marker_offsets = {k: v[1] for k, v in shapes.items()}
        tof = self.sensor_groups.get("tof", [])
        self.rays = None
        if tof:
            self.rays = scene.add_line_segments(
                "/live/tof_rays", np.zeros((len(tof), 2, 3), dtype=np.float32),
                np.tile(np.array((255, 80, 80), dtype=np.uint8), (len(tof), 2, 1)), thickness=0.006,
            )
        self.labels = [scene.add_label(f"/live/labels/{i}", name, font_screen_scale=0.75, anchor="center-left")
                       for i, name in enumerate(self.label_names)]

    # ------------------------------------------------------------------ drawing
    def auto_overscale(self, state: BeamState, current: float) -> float:
        """The overscale that keeps the largest drawn elastic deflection of the last seconds near
        ``AUTO_TARGET_FRACTION`` of the length (``current`` while the picture is readable)."""
        if self.shape_eta_xi is None or state.b_xi.size == 0:
            peak = float(np.max(np.abs(self.shape_eta @ state.b)))
        else:  # both planes: the deflection's magnitude
            peak = float(np.max(np.hypot(self.shape_eta @ state.b, self.shape_eta_xi @ state.b_xi)))
        self._envelope = max(peak, self._envelope * AUTO_DECAY_PER_FRAME)
        if self._envelope <= 0:
            return current
        wanted = AUTO_TARGET_FRACTION * self.feed.length / self._envelope
        drawn = current * self._envelope / (AUTO_TARGET_FRACTION * self.feed.length)
        if 0.4 <= drawn <= 1.6:  # hysteresis: keep a steady factor while the picture is readable
            return current
        return nice_scale(min(max(wanted, 1.0), MAX_OVERSCALE))

    def reset_envelope(self) -> None:
        self._envelope = 0.0

    def _lateral(self, state: BeamState, eta: np.ndarray, opt: SceneOptions) -> np.ndarray:
        """World y of the centre line at ``eta``: the ξ deflection of a beam that bends in two planes."""
        return lateral(state, self.feed.units_xi, eta, elastic_scale=opt.elastic_scale, standing=self.feed.standing)

    def _line(self, state: BeamState, eta: np.ndarray, opt: SceneOptions, **kwargs: Any) -> np.ndarray:
        return centreline(state, self.feed.units, eta, elastic_scale=opt.elastic_scale, rigid_scale=opt.rigid_scale, **kwargs)

    def render(self, est: "Estimate", mean: BeamState | None, opt: SceneOptions, *, texts: bool) -> None:
        """Draw ``est`` (labels and texts only when ``texts``: HTML labels cost the browser)."""
        state = est.state
        line = self._line(state, self.eta, opt)
        self.beam.vertices = ribbon(line, self.widths, standing=self.feed.standing, offset=self._lateral(state, self.eta, opt))
        self._render_ghost(mean, opt)
        self._render_truth(est, opt)
        d_world = np.array([opt.rigid_scale * state.d, 0.0, self.up * opt.rigid_scale * state.h], dtype=np.float32)
        self._render_support(state, d_world, opt, texts)
        self._render_sensors(state, est.sensor_states, d_world, opt)
        if texts:
            self._render_texts(state, line, opt)

    def _render_ghost(self, mean: BeamState | None, opt: SceneOptions) -> None:
        self.ghost.visible = opt.ghost
        if not opt.ghost:
            return
        if opt.running_mean_ghost and mean is not None:
            ghost = self._line(mean, self.eta, opt)
        else:
            ghost = centreline(self._rest(), self.feed.units, self.eta)
        self.ghost.vertices = ribbon(ghost, self.widths, standing=self.feed.standing)

    def _render_truth(self, est: "Estimate", opt: SceneOptions) -> None:
        feed = self.feed
        on = est.truth_deflection is not None and opt.truth
        self.truth.visible = on
        if not on:
            return
        first = feed.stations[0] > 0
        eta = np.concatenate([[0.0], feed.stations]) if first else feed.stations
        delta = np.concatenate([[0.0], est.truth_deflection]) if first else est.truth_deflection
        line = self._line(est.state, eta, opt, deflection=delta)
        self.truth.points = segments(to_world(line, y=0.5 * feed.width + 0.01, standing=feed.standing))

    def _render_support(self, state: BeamState, d_world: np.ndarray, opt: SceneOptions, texts: bool) -> None:
        up = self.up
        if self.bearing is not None:
            self.bearing.position = tuple(float(v) for v in d_world)
        if self.tangent is not None:
            phi = opt.rigid_scale * state.phi
            tip = d_world + np.array([math.sin(phi), 0.0, up * math.cos(phi)])
            self.tangent.points = np.array([[d_world, tip]], dtype=np.float32)
        if self.clamp:
            boxes = clamp_boxes(state, self.feed.width, rigid_scale=opt.rigid_scale, standing=self.feed.standing)
            for handle, (centre, _) in zip(self.clamp, boxes):
                handle.position = centre
            if texts and self.clamp_label is not None:
                self.clamp_label.position = (float(d_world[0]) - 0.12, 0.0, float(d_world[2]) - up * 0.05)

    def _colours(self, states: dict[str, str], topics: list[str]) -> np.ndarray:
        unknown = STATE_COLOURS["unknown"]
        return np.array([STATE_COLOURS.get(states.get(t, "unknown"), unknown) for t in topics], dtype=np.uint8)

    def _render_sensors(self, state: BeamState, states: dict[str, str], d_world: np.ndarray, opt: SceneOptions) -> None:
        feed = self.feed
        if self.bearing_topic is not None:
            self.bearing_marker.points = (d_world + np.array([0.0, 0.0, -self.up * 0.13], dtype=np.float32))[None, :]
            self.bearing_marker.colors = self._colours(states, [self.bearing_topic])
        for kind, items in self.sensor_groups.items():
            eta = np.array([e for _, e in items])
            pos = to_world(self._line(state, eta, opt), y=self.marker_offsets[kind] + self._lateral(state, eta, opt),
                           standing=feed.standing)
            if kind == "strain":  # on the +ζ face
                pos[:, 0] += 0.01
            self.markers[kind].points = pos
            self.markers[kind].colors = self._colours(states, [t for t, _ in items])
        if self.rays is None:
            return
        self.rays.visible = opt.rays
        if opt.rays:
            items = self.sensor_groups["tof"]
            rays = tof_rays(state, feed.units, np.array([e for _, e in items]), float(feed.reflector_distance or 0.0),
                            elastic_scale=opt.elastic_scale, rigid_scale=opt.rigid_scale, standing=feed.standing)
            rays[:, :, 1] = self.marker_offsets["tof"]
            self.rays.points = rays
            cols = np.array([_RAY_COLOURS.get(states.get(t, "ok"), _RAY_COLOURS["ok"]) for t, _ in items], dtype=np.uint8)
            self.rays.colors = np.repeat(cols[:, None, :], 2, axis=1)

    def _render_texts(self, state: BeamState, line: np.ndarray, opt: SceneOptions) -> None:
        feed = self.feed
        if self.labels:
            pos = to_world(self._line(state, self.label_eta, opt), y=0.5 * feed.width + 0.1 + self._lateral(state, self.label_eta, opt),
                           standing=feed.standing)
            for handle, p in zip(self.labels, pos):
                handle.visible = opt.labels
                if opt.labels:
                    handle.position = (float(p[0]), float(p[1]), float(p[2]))
        tip = line[-1]
        tip_y = float(self._lateral(state, np.array([feed.length]), opt)[0])
        self.tip_label.position = (float(tip[1]), tip_y, float(self.up * (tip[0] + 0.08)))
        delta_tip = float(feed.units.shape(np.array([feed.length]))[0] @ state.b)
        if feed.units_xi is None:
            self.tip_label.text = f"tip Δ = {1e3 * delta_tip:+.1f} mm  (×{opt.elastic_scale:g})"
        else:
            delta_xi = float(feed.units_xi.shape(np.array([feed.length]))[0] @ state.b_xi)
            self.tip_label.text = f"tip Δζ = {1e3 * delta_tip:+.1f} mm, Δξ = {1e3 * delta_xi:+.1f} mm  (×{opt.elastic_scale:g})"
