"""``shm estimate``: the IMMS estimator over a recording, scored against its truth when it has one."""

from __future__ import annotations

import argparse
from ._common import CliError, _model_from_args, _print_json, _recording_problems

__all__ = ['cmd_estimate']


def cmd_estimate(args: argparse.Namespace) -> int:
    from ..processing.estimation import estimate_recording, score_against_truth, truth_from_recording, write_estimates
    from ..recording import read_recording

    rec = read_recording(args.recording, rig=args.rig)
    model = _model_from_args(rec.rig, args)
    try:
        result = estimate_recording(rec, model)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    if args.out:
        write_estimates(args.out, rec, result)
    summary = {
        "samples": int(result.t.size),
        # Samples the reader refused (NaN, malformed, duplicate, backwards) plus the filter's gate.
        "rejected": int(result.diagnostics["rejected"] + sum(r.rejected for r in rec.report.topics.values())),
        "realtime_factor": round(float((result.t[-1] - result.t[0]) / max(result.filter_seconds, 1e-9)), 1),
        "selection": result.model.selection.as_dict(),
        "modes": result.model.gamma,
        **({"modes_xi": result.model.gamma_xi} if result.model.biaxial else {}),
        "rest_end_s": round(float(result.calibration.rest_end), 3),
        "diagnostics": result.diagnostics,
        **_recording_problems(rec),
    }
    truth = truth_from_recording(rec)
    if truth is not None:
        scores = score_against_truth(result, truth, after=result.calibration.rest_end)
        summary = {"rmse": scores["rmse"], **summary, "nees": scores["nees"], "scored_samples": scores["scored_samples"]}
    if args.json:
        _print_json(summary)
    else:
        sel = result.model.selection
        print(f"{sel.peripheral}, Γ = {result.model.gamma}: IMUs {','.join(sel.imus)}; ToFs {','.join(sel.tofs) or '-'}; "
              f"gauges {','.join(sel.gauges) or '-'} (aiding b{','.join(map(str, sel.aided)) or '-'})")
        print(f"{summary['samples']} samples, {summary['rejected']} rejected, {summary['realtime_factor']}x real time")
        for problem in result.diagnostics.get("problems", ()):
            print(f"warning: {problem}")
        if "rmse" in summary:
            r = summary["rmse"]
            print(f"RMSE after the rest phase: phi {r['phi_deg']:.4f} deg, e {1000 * r['e_m']:.3f} mm, d {1000 * r['d_m']:.3f} mm, "
                  f"deflection {1000 * r['deflection_m']:.3f} mm, curvature {r['curvature_per_m']:.2e} 1/m")
        for problem in summary["recording_problems"]:
            print(f"problem: {problem}")
        if args.out:
            print(f"wrote {args.out}")
    return 0
