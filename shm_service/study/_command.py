"""``shm study``: run the study (or reuse its table for design mode), write figures, report."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TextIO

from ._config import Configuration, StudySettings, benchmark
from ._design import DesignTargets, cheapest
from ._figures import example_tofs, figure_configurations, make_design_figure, make_study_figures
from ._study import ConfigurationResult, StudyResult, load_results, run_study, series_of


def orderings(rows: tuple[ConfigurationResult, ...]) -> dict[str, dict]:
    """The paper's qualitative findings checked on a study's table (RMSE against the truth,
    means over seeds). Each entry: ``holds`` and the numbers compared."""
    find = {r.config: r for r in rows}

    def pair(a: Configuration, b: Configuration, keys=("phi_deg", "e_m")) -> dict | None:
        ra, rb = find.get(a), find.get(b)
        if ra is None or rb is None:
            return None
        return {"holds": all(ra.rmse_truth[k] <= rb.rmse_truth[k] for k in keys),
                **{k: [ra.rmse_truth[k], rb.rmse_truth[k]] for k in keys}}

    out: dict[str, dict] = {}
    got = pair(benchmark(), Configuration(peripheral="acc", imus=4, tofs=4, gauges=4), ("phi_deg", "e_m", "deflection_m"))
    if got:
        out["gyro at least as good as acc at the benchmark counts"] = got
    for p in ("gyro", "acc"):
        got = pair(benchmark(), Configuration(peripheral=p, imus=4, tofs=4, gauges=0))
        if got:
            out[f"{p} without gauges worse than the benchmark"] = got
        got = pair(Configuration(peripheral=p, imus=4, tofs=5, gauges=0), Configuration(peripheral=p, imus=4, tofs=4, gauges=0))
        if got:
            out[f"{p}: one extra ToF better than none (ν_ε = 0)"] = got
    return out


def _row_text(r: ConfigurationResult) -> str:
    t, ts, b = r.rmse_truth, r.rmse_truth_std, r.rmse_benchmark
    bb = " ".join(f"{1000 * v:6.3f}" for v in b["b"])
    return (f"{r.config.peripheral:4s} {r.config.imus:3d} {r.config.tofs:3d} {r.config.gauges:3d} {r.boards:3d} | "
            f"{t['phi_deg']:.4f}±{ts['phi_deg']:.4f} {1000 * t['e_m']:6.3f}±{1000 * ts['e_m']:5.3f} "
            f"{1000 * t['deflection_m']:6.3f} | {b['phi_deg']:.4f} {1000 * b['e_m']:6.3f} {bb}")


_HEADER = ("per  ν_s ν_ρ ν_ε brd | truth: φ [°] ± std   e [mm] ± std  defl[mm] | bm: φ [°] e [mm] "
           "b1..b4 [mm]")


def _summary(result: StudyResult, stream: TextIO) -> None:
    s = result.settings
    ex = example_tofs(s)
    key = [c for c in result.settings.configurations()
           if c.gauges == 4 or (c.gauges == 0 and c.imus == 4 and c.tofs in (min(s.tofs), 5, ex, max(s.tofs)))
           or (c.gauges and c.tofs == ex)]
    print(_HEADER, file=stream)
    for c in key:
        r = result.find(c)
        if r is not None:
            print(_row_text(r), file=stream)
    print("orderings (RMSE against the truth, mean over seeds):", file=stream)
    for name, got in orderings(result.results).items():
        nums = "; ".join(f"{k} {a:.4g} vs {b:.4g}" for k, (a, b) in ((k, v) for k, v in got.items() if k != "holds"))
        print(f"  {'holds' if got['holds'] else 'FAILS'}: {name} ({nums})", file=stream)


def run_command(settings: StudySettings, out: str | Path, *, targets: DesignTargets | None = None,
                keep_recordings: bool = False, progress: TextIO | None = sys.stderr, stdout: TextIO = sys.stdout,
                top: int = 3) -> int:
    """The ``shm study`` command; returns the exit code (1: no configuration meets the targets)."""
    out = Path(out)
    rows = load_results(out, settings) if targets is not None else None
    if rows is None and (out / "study.json").is_file():  # recordings kept by an earlier study are stale now
        import shutil

        shutil.rmtree(out / "recordings", ignore_errors=True)
    result: StudyResult | None = None
    if rows is not None:
        print(f"reusing the study table in {out}/results.json (same settings)", file=stdout)
    else:
        result = run_study(settings, out, progress=progress,
                           series_for=figure_configurations(settings) if settings.rig is None else (),
                           keep_recordings=keep_recordings)
        # the paper's figures (Figs. 15-19) are drawn for its sheet's sweeps; a rig file's study is its table
        figures = make_study_figures(result, out) if settings.rig is None else []
        rows = result.results
        print(f"study: {len(rows)} configurations × {len(settings.seeds)} seeds in {result.wall_seconds:.0f} s "
              f"on {result.workers} workers; wrote {out}/results.csv, results.json, study.json and "
              f"{len(figures)} figures", file=stdout)
        _summary(result, stdout)
    if targets is None:
        return 0
    chosen = cheapest(rows, targets)
    wanted = ", ".join(f"{k} ≤ {v:g}" for k, v in targets.model_dump().items() if v is not None)
    if not chosen:
        best_phi = min(rows, key=lambda r: r.rmse_truth["phi_deg"] + r.rmse_truth_std["phi_deg"])
        best_e = min(rows, key=lambda r: r.rmse_truth["e_m"] + r.rmse_truth_std["e_m"])
        print(f"design: no configuration meets {wanted} (mean + std over seeds, against the truth); "
              f"best φ {best_phi.rmse_truth['phi_deg'] + best_phi.rmse_truth_std['phi_deg']:.4f}° ({best_phi.config.label}), "
              f"best e {best_e.rmse_truth['e_m'] + best_e.rmse_truth_std['e_m']:.4g} m ({best_e.config.label})", file=stdout)
        import json

        (out / "design.json").write_text(json.dumps({"targets": targets.model_dump(), "configurations": []}, indent=2) + "\n")
        return 1
    shown = chosen[:top]
    # the design figures need time series (a re-run of the first seed); a rig file's study draws none
    series, bench = (series_of(settings, [r.config for r in shown], out, progress=progress) if settings.rig is None
                     else ({}, {}))
    base = result or StudyResult(settings=settings, results=rows, wall_seconds=0.0, workers=0)
    base = StudyResult(settings=settings, results=rows, wall_seconds=base.wall_seconds, workers=base.workers,
                       series=series, benchmark_series=bench)
    import json

    configurations: list[dict[str, object]] = []
    design = {"targets": targets.model_dump(), "criterion": "mean + std over seeds of the RMSE against the truth",
              "configurations": configurations}
    print(f"design: {len(chosen)} configurations meet {wanted}; cheapest first (fewest gauges, then boards):", file=stdout)
    print(_HEADER, file=stdout)
    for rank, r in enumerate(chosen, start=1):
        entry = {**r.as_json(), "boards": r.boards, "sensors": r.selection, "rank": rank}
        if rank <= top and settings.rig is None:
            entry["figure"] = make_design_figure(base, r, rank, out).name
            print(_row_text(r) + f"  → {entry['figure']}", file=stdout)
        elif rank <= top:
            print(_row_text(r), file=stdout)
        configurations.append(entry)
    (out / "design.json").write_text(json.dumps(design, indent=2, allow_nan=False) + "\n")
    print(f"wrote {out}/design.json", file=stdout)
    return 0
