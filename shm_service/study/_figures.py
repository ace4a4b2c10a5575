"""Figures of the kind of the paper's Figures 15–22 (PNG, Agg canvas; no pyplot state)."""

from __future__ import annotations

from pathlib import Path
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ._config import GAMMA, Configuration, StudySettings, benchmark
from ._study import ConfigurationResult, StudyResult

COLORS = {"gyro": "tab:blue", "acc": "tab:orange"}
BM_STYLE = {"color": "black", "lw": 1.0, "label": "bm (gyro 4/4/4)"}
TRUTH_STYLE = {"color": "0.55", "lw": 0.8, "ls": ":", "label": "sim (truth)"}


def example_tofs(settings: StudySettings) -> int:
    """ν_ρ of the paper's example configurations (10), or the largest the study has."""
    return 10 if 10 in settings.tofs else max(settings.tofs)


def _no_gauges(p: str, tofs: int = 4) -> Configuration:
    return Configuration(peripheral=p, imus=4, tofs=tofs, gauges=0)


def figure_configurations(settings: StudySettings) -> set[Configuration]:
    """Configurations whose time series the figures need (first seed)."""
    ex = example_tofs(settings)
    wanted = {benchmark()}
    for p in settings.peripherals:
        wanted |= {_no_gauges(p, min(settings.tofs)), _no_gauges(p, ex)}
        for g in settings.reduced_gauges:
            wanted.add(Configuration(peripheral=p, imus=4, tofs=ex, gauges=g))
    return wanted & set(settings.configurations())


def _after(series: dict, bench: dict) -> np.ndarray:
    return series["t"] >= max(float(series["rest_end"]), float(bench["rest_end"]))


def _dynamic_window(bench: dict, length: float) -> tuple[float, float]:
    """The interval of highest dynamics: the window where the benchmark's e varies most."""
    t, e = bench["t"], bench["e"]
    start, end = float(bench["rest_end"]), float(t[-1])
    length = min(length, end - start)
    best, best_var = start, -1.0
    for lo in np.arange(start, end - length + 1e-9, length / 4):
        m = (t >= lo) & (t < lo + length)
        if m.sum() > 10 and np.var(e[m]) > best_var:
            best, best_var = float(lo), float(np.var(e[m]))
    return best, best + length


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    return path


def _plot_phi_e(axes, result: StudyResult, configs: list[Configuration], window: tuple[float, float] | None = None) -> None:
    bench = result.benchmark_series
    t = bench["t"]
    m = slice(None) if window is None else (t >= window[0]) & (t <= window[1])
    ax_phi, ax_e = axes
    ax_phi.plot(t[m], np.degrees(bench["truth_phi"][m]), **TRUTH_STYLE)
    ax_e.plot(t[m], 1000 * bench["truth_e"][m], **TRUTH_STYLE)
    ax_phi.plot(t[m], np.degrees(bench["phi"][m]), **BM_STYLE)
    ax_e.plot(t[m], 1000 * bench["e"][m], **BM_STYLE)
    for c in configs:
        s = result.series.get(c)
        if s is None:
            continue
        ms = slice(None) if window is None else (s["t"] >= window[0]) & (s["t"] <= window[1])
        ls = "--" if c.peripheral == "acc" else "-"
        ax_phi.plot(s["t"][ms], np.degrees(s["phi"][ms]), ls=ls, lw=0.9, color=COLORS[c.peripheral], label=c.label)
        ax_e.plot(s["t"][ms], 1000 * s["e"][ms], ls=ls, lw=0.9, color=COLORS[c.peripheral], label=c.label)
    ax_phi.set_ylabel("φ [°]")
    ax_e.set_ylabel("e [mm]")
    ax_e.set_xlabel("t [s]")
    ax_phi.legend(fontsize=7, loc="upper left")
    for ax in axes:
        ax.grid(alpha=0.3)


def _plot_b(axes, result: StudyResult, configs: list[Configuration], units: list[int], window: tuple[float, float]) -> None:
    bench = result.benchmark_series
    t = bench["t"]
    m = (t >= window[0]) & (t <= window[1])
    for ax, k in zip(axes, units):
        ax.plot(t[m], 1000 * bench["b"][m, k - 1], **BM_STYLE)
        for c in configs:
            s = result.series.get(c)
            if s is None:
                continue
            ms = (s["t"] >= window[0]) & (s["t"] <= window[1])
            ax.plot(s["t"][ms], 1000 * s["b"][ms, k - 1], lw=0.9, ls="--" if c.peripheral == "acc" else "-",
                    color=COLORS[c.peripheral], label=c.label)
        ax.set_ylabel(f"b{k} [mm]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left")
    axes[-1].set_xlabel("t [s]")


def _beam_snapshot(ax, result: StudyResult, configs: list[Configuration], at: float) -> None:
    """Deformed beams at one instant (paper Fig. 15 right): bearing D, bending line, ToFs, tangent at D.

    The benchmark's attitude and deflection are overscaled by ``scale``; the differences of the
    other configurations to the benchmark by the larger ``gain`` (they are millimetres)."""
    from estimator import build_model

    from ..rig_layouts import default_rig

    rig = default_rig(result.settings.layout)
    length = rig.beam.length
    eta = np.linspace(0.0, length, 200)
    bench = result.benchmark_series
    i = int(np.clip(np.searchsorted(bench["t"], at), 0, bench["t"].size - 1))
    model_of = lambda c: build_model(rig, peripheral=c.peripheral, modes=GAMMA, imus=c.imus, tofs=c.tofs,  # noqa: E731
                                     gauges=c.gauges, aided=c.aided if c.gauges else None)
    bm_model = model_of(benchmark())
    units = bm_model.units  # same rig and Γ: the unit deformations of every configuration
    phi_bm, b_bm = float(bench["phi"][i]), bench["b"][i].astype(float)
    states = [("bm", bm_model, phi_bm, b_bm, "black", "-")]
    for c in configs:
        s = result.series.get(c)
        if s is None:
            continue
        j = int(np.clip(np.searchsorted(s["t"], at), 0, s["t"].size - 1))
        states.append((c.label, model_of(c), float(s["phi"][j]), s["b"][j].astype(float), COLORS[c.peripheral],
                       "--" if c.peripheral == "acc" else "-"))
    tip_bm = abs(float((units.shape(np.array([length])) @ b_bm)[0]))
    scale = min(0.15 * length / max(tip_bm, 1e-9), 0.2 / max(abs(phi_bm), 1e-9))
    diff = max([abs(p - phi_bm) * length + float(np.max(np.abs(units.shape(eta) @ (b - b_bm))))
                for _, _, p, b, _, _ in states[1:]] + [1e-9])
    gain = max(scale, 0.25 * length / diff)
    for label, model, phi, b, color, ls in states:
        p = scale * phi_bm + gain * (phi - phi_bm)
        delta_of = lambda x: units.shape(x) @ (scale * b_bm + gain * (b - b_bm))  # noqa: E731, B023
        delta = delta_of(eta)
        x = np.sin(p) * eta + np.cos(p) * delta
        y = -(np.cos(p) * eta - np.sin(p) * delta)
        ax.plot(x, y, color=color, ls=ls, lw=1.2, label=label)
        ax.plot([0, np.sin(p) * length], [0, -np.cos(p) * length], color=color, ls="-.", lw=0.6)
        if model.tof_eta.size:
            d = delta_of(model.tof_eta)
            ax.plot(np.sin(p) * model.tof_eta + np.cos(p) * d, -(np.cos(p) * model.tof_eta - np.sin(p) * d), "o", ms=3,
                    color=color)
    ax.plot([0], [0], "o", ms=9, mfc="none", mec="black")
    ax.axvline(0, color="0.7", lw=0.6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"ζ [m]: bm ×{scale:.0f}, differences to bm ×{gain:.0f}")
    ax.set_ylabel("ξ [m]")
    ax.set_title(f"t = {at:.0f} s (ToFs as dots, tangent at D dash-dotted)", fontsize=9)
    ax.legend(fontsize=6, loc="lower left")


def _plot_deviation(axes, result: StudyResult, configs: list[Configuration]) -> None:
    """φ − φ_bm and e − e_bm over the run (the truth's deviation from bm in grey)."""
    bench = result.benchmark_series
    t = bench["t"]
    ax_phi, ax_e = axes
    ax_phi.plot(t, np.degrees(bench["truth_phi"] - bench["phi"]), **{**TRUTH_STYLE, "label": "sim − bm"})
    ax_e.plot(t, 1000 * (bench["truth_e"] - bench["e"]), **{**TRUTH_STYLE, "label": "sim − bm"})
    for c in configs:
        s = result.series.get(c)
        if s is None:
            continue
        ref_phi = np.interp(s["t"], t, bench["phi"])
        ref_e = np.interp(s["t"], t, bench["e"])
        ls = "--" if c.peripheral == "acc" else "-"
        ax_phi.plot(s["t"], np.degrees(s["phi"] - ref_phi), ls=ls, lw=0.7, color=COLORS[c.peripheral], label=c.label + " − bm")
        ax_e.plot(s["t"], 1000 * (s["e"] - ref_e), ls=ls, lw=0.7, color=COLORS[c.peripheral], label=c.label + " − bm")
    ax_phi.set_ylabel("φ − φ_bm [°]")
    ax_e.set_ylabel("e − e_bm [mm]")
    ax_e.set_xlabel("t [s]")
    ax_phi.legend(fontsize=7, loc="upper left")
    for ax in axes:
        ax.axhline(0, color="black", lw=0.6)
        ax.grid(alpha=0.3)


def _errorbar(ax, x, mean, std, **kw) -> None:
    ax.errorbar(x, mean, yerr=std, capsize=2, marker="o", ms=3, lw=1, **kw)


def _rows(result: StudyResult, **match) -> list[ConfigurationResult]:
    rows = [r for r in result.results if all(getattr(r.config, k) == v for k, v in match.items())]
    return sorted(rows, key=lambda r: r.config.tofs)


def _metric(r: ConfigurationResult, against: str, key: str) -> tuple[float, float]:
    """(mean, std) of one RMSE in display units (° for φ, mm for e and b)."""
    # against the benchmark, "b" holds a list (one RMSE per Γ): the tables are read by key
    truth = against == "truth"
    table: dict[str, Any] = r.rmse_truth if truth else r.rmse_benchmark
    std: dict[str, Any] = r.rmse_truth_std if truth else r.rmse_benchmark_std
    if key.startswith("b"):
        k = int(key[1:]) - 1
        return 1000 * table["b"][k], 1000 * std["b"][k]
    factor = 1.0 if key == "phi_deg" else 1000.0
    return factor * table[key], factor * std[key]


_LABEL = {"phi_deg": "Δφ_rmse [°]", "e_m": "Δe_rmse [mm]", "b3": "Δb3_rmse [mm]", "b4": "Δb4_rmse [mm]"}


def make_study_figures(result: StudyResult, out: Path) -> list[Path]:
    """The paper's Figs. 15–22 of the study ``result``, written to ``out``; returns the files."""
    s = result.settings
    ex = example_tofs(s)
    bench = result.benchmark_series
    duration = float(bench["t"][-1])
    window = _dynamic_window(bench, 30.0 if duration >= 200 else 15.0)
    peripherals = [p for p in ("acc", "gyro") if p in s.peripherals]
    no_gauges = [_no_gauges(p, min(s.tofs)) for p in peripherals]
    extra = [_no_gauges(p, ex) for p in peripherals]
    written = [
        _fig15(result, out, no_gauges, bench, duration),
        _fig_b(result, out / "fig16_b_without_gauges.png", no_gauges, window,
               "Deformation variables without strain gauges (cf. paper Fig. 16)"),
        _fig17(result, out, peripherals),
        _fig18(result, out, extra, ex),
        _fig_b(result, out / "fig19_b_extra_tofs.png", extra, window,
               f"Deformation variables with additional ToFs (ν_ρ = {ex}) (cf. paper Fig. 19)"),
    ]
    if s.reduced_gauges:
        styles = {g: ls for g, ls in zip(sorted(s.reduced_gauges), ("-", "--", ":"))}
        written.append(_fig20(result, out, peripherals, ex, styles))
        written.append(_fig21(result, out, peripherals, styles))
        written += _fig22(result, out, ex, window)
    return written


def _fig15(result: StudyResult, out: Path, no_gauges: list, bench: dict, duration: float) -> Path:
    # Fig. 15: drift of φ and e without gauges, and the overscaled beams at one instant.
    fig = Figure(figsize=(13, 9), layout="constrained")
    grid = fig.add_gridspec(4, 3)
    axes = [fig.add_subplot(grid[k, :2]) for k in range(4)]
    _plot_phi_e(axes[:2], result, no_gauges)
    _plot_deviation(axes[2:], result, no_gauges)
    at = 230.0 if duration >= 240 else float(bench["rest_end"]) + 0.75 * (duration - float(bench["rest_end"]))
    for ax in axes:
        ax.axvline(at, color="0.6", lw=0.6)
    _beam_snapshot(fig.add_subplot(grid[:, 2]), result, no_gauges, at)
    fig.suptitle("Without strain gauges (ν_ε = 0) against the benchmark (cf. paper Fig. 15)")
    return _save(fig, out / "fig15_drift_without_gauges.png")


def _fig_b(result: StudyResult, path: Path, configs: list, window: Any, title: str) -> Path:
    """b of ``configs`` in the interval of high dynamics (Figs. 16, 19)."""
    fig = Figure(figsize=(10, 8), layout="constrained")
    _plot_b([fig.add_subplot(GAMMA, 1, k) for k in range(1, GAMMA + 1)], result, configs, list(range(1, GAMMA + 1)), window)
    fig.suptitle(title)
    return _save(fig, path)


def _fig17(result: StudyResult, out: Path, peripherals: Sequence[str]) -> Path:
    s = result.settings
    # Fig. 17: RMSE against ν_ρ without gauges, ν_s = 4, 5.
    fig = Figure(figsize=(11, 7), layout="constrained")
    axes = fig.subplots(2, 2)
    for row, against in enumerate(("benchmark", "truth")):
        for col, key in enumerate(("phi_deg", "e_m")):
            ax = axes[row, col]
            for p in peripherals:
                for imus in s.imus:
                    rows = _rows(result, peripheral=p, imus=imus, gauges=0)
                    if rows:
                        mean, std = zip(*(_metric(r, against, key) for r in rows))
                        _errorbar(ax, [r.config.tofs for r in rows], mean, std, color=COLORS[p],
                                  ls="-" if imus == 4 else ":", label=f"{p} ν_s={imus}")
            if against == "truth":
                for p in peripherals:
                    r = result.find(Configuration(peripheral=p, imus=4, tofs=4, gauges=4))
                    if r is not None:
                        ax.axhline(_metric(r, "truth", key)[0], color=COLORS[p], lw=0.8, ls="-.", label=f"{p} 4/4/4 (bm counts)")
            ax.set_title(f"against the {'benchmark (Eq. 21)' if against == 'benchmark' else 'simulator truth'}", fontsize=9)
            ax.set_ylabel(_LABEL[key])
            ax.set_xlabel("ν_ρ (ToFs), ν_ε = 0")
            ax.grid(alpha=0.3)
            ax.set_ylim(bottom=0)
    axes[0, 0].legend(fontsize=7)
    axes[1, 0].legend(fontsize=7)
    fig.suptitle("RMSE with additional ToFs, no strain gauges; mean ± std over seeds (cf. paper Fig. 17)")
    return _save(fig, out / "fig17_rmse_vs_tofs.png")


def _fig18(result: StudyResult, out: Path, extra: list, ex: int) -> Path:
    fig = Figure(figsize=(11, 8), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True)
    _plot_phi_e(axes[:2], result, extra)
    _plot_deviation(axes[2:], result, extra)
    fig.suptitle(f"With additional ToFs (ν_ρ = {ex}, ν_ε = 0) (cf. paper Fig. 18)")
    return _save(fig, out / "fig18_extra_tofs.png")


def _fig20(result: StudyResult, out: Path, peripherals: Sequence[str], ex: int, styles: dict) -> Path:
    s = result.settings
    # Fig. 20: RMSE of φ and e with reduced gauges, against ν_ρ and against ν_ε.
    fig = Figure(figsize=(11, 7), layout="constrained")
    axes = fig.subplots(2, 2)
    ref = result.find(_no_gauges("gyro", ex))
    for col, key in enumerate(("phi_deg", "e_m")):
        ax = axes[0, col]
        for p in peripherals:
            for g in s.reduced_gauges:
                rows = _rows(result, peripheral=p, imus=4, gauges=g)
                mean, std = zip(*(_metric(r, "benchmark", key) for r in rows))
                _errorbar(ax, [r.config.tofs for r in rows], mean, std, color=COLORS[p], ls=styles[g], label=f"{p} ν_ε={g}")
        if ref is not None:
            ax.axhline(_metric(ref, "benchmark", key)[0], color="black", ls="-.", lw=1, label=f"gyro ν_ρ={ex}, ν_ε=0")
        ax.set_xlabel("ν_ρ (ToFs)")
        ax.set_ylabel(_LABEL[key])
        ax.set_title("against the benchmark (Eq. 21)", fontsize=9)
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0)
        ax = axes[1, col]
        for p in peripherals:
            found = [result.find(_no_gauges(p, ex))] + [result.find(Configuration(peripheral=p, imus=4, tofs=ex, gauges=g))
                                                        for g in sorted(s.reduced_gauges)]
            rows = [r for r in found if r is not None]
            mean, std = zip(*(_metric(r, "truth", key) for r in rows))
            _errorbar(ax, [r.config.gauges for r in rows], mean, std, color=COLORS[p], label=f"{p} ν_ρ={ex}")
            r4 = result.find(Configuration(peripheral=p, imus=4, tofs=4, gauges=4))
            if r4 is not None:
                m4, s4 = _metric(r4, "truth", key)
                ax.errorbar([GAMMA], [m4], yerr=[s4], marker="s", color=COLORS[p], capsize=2, ls="none",
                            label=f"{p} ν_ρ=4, ν_ε=4")
        ax.set_xlabel("ν_ε (strain gauges)")
        ax.set_ylabel(_LABEL[key])
        ax.set_title("against the simulator truth", fontsize=9)
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0)
    axes[0, 0].legend(fontsize=7)
    axes[1, 0].legend(fontsize=7)
    fig.suptitle("RMSE with a reduced number of strain gauges (restricted aiding, Eq. 22) (cf. paper Fig. 20)")
    return _save(fig, out / "fig20_rmse_vs_gauges.png")


def _fig21(result: StudyResult, out: Path, peripherals: Sequence[str], styles: dict) -> Path:
    s = result.settings
    # Fig. 21: RMSE of b3 and b4.
    fig = Figure(figsize=(11, 4), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, key in zip(axes, ("b3", "b4")):
        for p in peripherals:
            for g in s.reduced_gauges:
                rows = _rows(result, peripheral=p, imus=4, gauges=g)
                mean, std = zip(*(_metric(r, "benchmark", key) for r in rows))
                _errorbar(ax, [r.config.tofs for r in rows], mean, std, color=COLORS[p], ls=styles[g], label=f"{p} ν_ε={g}")
        ax.set_xlabel("ν_ρ (ToFs)")
        ax.set_ylabel(_LABEL[key] + " against bm")
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0)
    axes[0].legend(fontsize=7)
    fig.suptitle("RMSE of b3 and b4 with a reduced number of strain gauges (cf. paper Fig. 21)")
    return _save(fig, out / "fig21_rmse_b3_b4.png")


def _fig22(result: StudyResult, out: Path, ex: int, window: Any) -> list[Path]:
    s = result.settings
    # Fig. 22: b3, b4 of acc with two gauges and gyro with one (or what the study has).
    pair = [Configuration(peripheral="acc", imus=4, tofs=ex, gauges=max(s.reduced_gauges) if 2 not in s.reduced_gauges else 2),
            Configuration(peripheral="gyro", imus=4, tofs=ex, gauges=min(s.reduced_gauges))]
    pair = [c for c in pair if c in result.series]
    if pair:
        fig = Figure(figsize=(10, 5), layout="constrained")
        _plot_b(fig.subplots(2, 1, sharex=True), result, pair, [3, 4], window)
        fig.suptitle("b3 and b4 with reduced strain gauges (cf. paper Fig. 22)")
        return [_save(fig, out / "fig22_b3_b4_reduced_gauges.png")]
    return []


def make_design_figure(result: StudyResult, row: ConfigurationResult, rank: int, out: Path) -> Path:
    """φ and e over the run, and b3, b4 in the interval of high dynamics, against bm and the truth."""
    bench = result.benchmark_series
    window = _dynamic_window(bench, 30.0 if float(bench["t"][-1]) >= 200 else 15.0)
    fig = Figure(figsize=(11, 11), layout="constrained")
    axes = fig.subplots(6, 1)
    _plot_phi_e(axes[:2], result, [row.config])
    _plot_deviation(axes[2:4], result, [row.config])
    _plot_b(axes[4:], result, [row.config], [3, 4], window)
    t = row.rmse_truth
    fig.suptitle(f"#{rank}: {row.config.label}, {row.boards} boards — RMSE vs truth φ {t['phi_deg']:.4f}°, "
                 f"e {1000 * t['e_m']:.2f} mm (mean over seeds {','.join(map(str, row.seeds))})", fontsize=10)
    return _save(fig, out / f"design_{rank}_{row.config.slug}.png")
