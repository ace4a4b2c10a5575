"""One browser's GUI panels: the controls above the tabs (header, a fleet's selector and overview,
pause, overscale), the alarms with their acknowledgement, the status, and the view settings."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import viser

from contract import AlarmDocument

from ._context import TREND_WINDOWS, ViewContext, ViewSettings
from ._html import MARKER_LEGEND, MODES_SHOWN, alarms_html, message_html, overview_html, status_html
from ._scene import AUTO_TARGET_FRACTION, MAX_OVERSCALE, SceneOptions

if TYPE_CHECKING:
    from ._feed import Snapshot, StructureFeed

__all__ = ["AlarmsPanel", "ControlsPanel", "SettingsPanel", "StatusPanel"]

log = logging.getLogger(__name__)
WAITING = "(waiting for the fleet)"


class ControlsPanel:
    """What does not depend on the structure shown: the header, pause, overscale, and for a
    fleet the structure selector and the overview."""

    def __init__(self, gui: Any, ctx: ViewContext, settings: ViewSettings) -> None:
        self.ctx, self.settings = ctx, settings
        self.header = gui.add_html("", order=0)
        self.wanted: str | None = None  # a fleet: the structure chosen (shown once its feed is ready)
        self._overview_version = -1
        self._overview_selected: str | None = None
        if ctx.fleet:
            self._build_fleet(gui)
        self.pause = gui.add_checkbox(
            "Pause live view", False, order=1,
            hint="Freezes this browser's beam, spectra and trends (alarms and status stay live). Never changes data.",
        )
        self.overscale = gui.add_slider(
            "Overscale (elastic)", 1.0, MAX_OVERSCALE, 1.0, settings.elastic_scale, order=2,
            hint="Multiplies the elastic deflection Σ b s(η) drawn, like the paper's Figure 15",
        )
        self.auto_scale = gui.add_checkbox(
            "Auto overscale", True, order=2.5,
            hint=f"Keeps the largest drawn elastic deflection of the last seconds near {AUTO_TARGET_FRACTION:.0%} of the beam length",
        )
        self.auto_changed = False

        @self.pause.on_update
        def _(_: Any) -> None:
            settings.paused = bool(self.pause.value)
            settings.dirty_scene = settings.dirty_trends = True

        @self.overscale.on_update
        def _(event: Any) -> None:
            settings.elastic_scale = float(self.overscale.value)
            if event.client is not None:  # moved by the operator (not by auto overscale)
                self.auto_scale.value = False
            settings.dirty_scene = True

        @self.auto_scale.on_update
        def _(_: Any) -> None:
            self.auto_changed = True
            settings.dirty_scene = True

    def _build_fleet(self, gui: Any) -> None:
        with gui.add_folder("Fleet", order=0.5):
            self.selector = gui.add_dropdown(
                "Structure", (WAITING,), initial_value=WAITING,
                hint="The structure this browser shows: its 3-D view, spectra, trends, alarms and status",
            )
            self.select_info = gui.add_html("")
            self.overview = gui.add_html(message_html("Waiting for the fleet…"))

        @self.selector.on_update
        def _(_: Any) -> None:
            value = str(self.selector.value)
            if value in self.ctx.structures.ids():
                self.wanted = value

    def choose(self, shown: "StructureFeed | None") -> str | None:
        """The structure to show now: the one chosen, else the first (a failed one last)."""
        structures = self.ctx.structures
        ids = tuple(structures.ids())
        if self.ctx.fleet and ids and tuple(self.selector.options) != ids:
            current = self.wanted
            self.selector.options = ids
            if current in ids:
                self.selector.value = current
        if self.wanted is None and ids and structures.overview is not None:
            ordered = sorted(structures.overview.structures, key=lambda s: s.state == "failed")
            self.wanted = next((s.id for s in ordered), ids[0])
            if self.ctx.fleet:
                self.selector.value = self.wanted
        return self.wanted

    def loading(self, text: str | None, error: bool = False) -> None:
        """A fleet: say which structure is being read or why it cannot be drawn."""
        if self.ctx.fleet:
            self.select_info.content = "" if text is None else message_html(text, "error" if error else "info")

    def render_overview(self, shown: str | None) -> None:
        structures = self.ctx.structures
        if not self.ctx.fleet:
            return
        if structures.overview_version != self._overview_version or shown != self._overview_selected:
            self._overview_version, self._overview_selected = structures.overview_version, shown
            self.overview.content = overview_html(structures.overview, structures.overview_error, shown)


class AlarmsPanel:
    """The alarm list and the acknowledgement (the operator token, the service's rules)."""

    def __init__(self, gui: Any, ctx: ViewContext, feed: "StructureFeed") -> None:
        self.ctx, self.feed = ctx, feed
        self.options: dict[str, int] = {}  # dropdown label -> alarm id
        self.list = gui.add_html(alarms_html((), str))
        self.choice = gui.add_dropdown("Alarm", ("(none)",), initial_value="(none)")
        self.token = gui.add_text("Operator token", "", hint="Required to acknowledge (same rules as the HTTP API)")
        self.button = gui.add_button("Acknowledge", icon=viser.Icon.CHECK, color="red")
        self.result = gui.add_html("")

        @self.button.on_click
        def _(_: Any) -> None:
            self.result.content = self.acknowledge()

    def label(self, a: AlarmDocument) -> str:
        mm = self.feed.mode_map
        if a.kind == "frequency" and a.mode is not None and a.mode in mm.modes:
            return mm.mode_label(a.mode)
        return a.chart

    def acknowledge(self) -> str:
        """Acknowledge the chosen alarm; the HTML that says how it went."""
        alarm_id = self.options.get(str(self.choice.value))
        if alarm_id is None:
            return message_html("Choose an alarm first.", "warn")
        try:
            result = self.ctx.acknowledge(alarm_id, str(self.token.value))
        except PermissionError as exc:
            return message_html(f"Not acknowledged: {str(exc) or 'token missing or wrong'}", "error")
        except KeyError:
            return message_html(f"Alarm #{alarm_id} does not exist.", "error")
        except Exception as exc:
            log.exception("acknowledge(%s) failed", alarm_id)
            return message_html(f"Acknowledge failed: {type(exc).__name__}: {exc}", "error")
        if isinstance(result, AlarmDocument):
            self.feed.upsert_alarm(result)
        return message_html(f"Alarm #{alarm_id} acknowledged.", "ok")

    def render(self, snap: "Snapshot") -> None:
        alarms = snap.alarms
        self.list.content = alarms_html(alarms, self.label)
        self.options = {f"#{a.id} {a.level} {self.label(a)}": a.id for a in alarms if not a.acknowledged}
        options = tuple(self.options) or ("(none)",)
        if tuple(self.choice.options) != options:
            current = self.choice.value
            self.choice.options = options
            if current in options:
                self.choice.value = current


class StatusPanel:
    def __init__(self, gui: Any, ctx: ViewContext) -> None:
        self.ctx = ctx
        self.html = gui.add_html(message_html("Waiting for the service status…"))

    def render(self, snap: "Snapshot") -> None:
        self.html.content = status_html(snap, self.ctx.stats())


class SettingsPanel:
    """The View tab: rigid overscale, ghost, truth, rays, labels, the modes shown, the trend window."""

    def __init__(self, gui: Any, settings: ViewSettings, unit_labels: dict[int, str],
                 on_units: Callable[[set[int]], None]) -> None:
        self.settings = settings
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
        gui.add_markdown(MODES_SHOWN)
        self.unit_boxes = {u: gui.add_checkbox(label, True) for u, label in unit_labels.items()}
        self.trend_window = gui.add_dropdown("Trend window", tuple(TREND_WINDOWS), initial_value="1 h")
        gui.add_markdown(MARKER_LEGEND)

        def scene_changed(_: Any) -> None:
            settings.rigid_scale = float(self.rigid.value)
            settings.dirty_scene = True

        for handle in (self.rigid, self.show_ghost, self.ghost_mode, self.show_truth, self.show_rays, self.show_labels):
            handle.on_update(scene_changed)

        def modes_changed(_: Any) -> None:
            settings.units_shown = {u for u, box in self.unit_boxes.items() if box.value}
            settings.trend_window_s = TREND_WINDOWS.get(str(self.trend_window.value), TREND_WINDOWS["all"])
            on_units(settings.units_shown)
            settings.dirty_trends = settings.dirty_spectra = True

        for handle in (*self.unit_boxes.values(), self.trend_window):
            handle.on_update(modes_changed)

    def options(self) -> SceneOptions:
        s = self.settings
        return SceneOptions(
            elastic_scale=s.elastic_scale, rigid_scale=s.rigid_scale, ghost=bool(self.show_ghost.value),
            running_mean_ghost=str(self.ghost_mode.value).startswith("running"), truth=bool(self.show_truth.value),
            rays=bool(self.show_rays.value), labels=bool(self.show_labels.value),
        )
