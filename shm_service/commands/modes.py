"""``shm modes``: the rig model's eigenfrequencies (against the paper's Table 1 when pinned and hanging)
and, with ``--calibration``, the shipped model update of the benchmark layout."""

from __future__ import annotations

import argparse
from ._common import CliError, _print_json, _rig_from_args

__all__ = ['cmd_modes']


def _plane_modes(rig, temperature_c, count: int, plane: str = "zeta"):
    """The FE model of one bending plane, its first ``count`` frequencies (Hz) and the unit
    deformation (1-based) each mode belongs to."""
    from estimator import assemble_beam, natural_modes, unit_deformations

    model = assemble_beam(rig, temperature_c=temperature_c, plane=plane)
    modes = natural_modes(model, max(count, 6))
    units = unit_deformations(modes, 5)
    unit_of_mode = {m: i + 1 for i, group in enumerate(units.modes) for m in group}
    return model, modes.frequencies_hz[:count], units, unit_of_mode


def cmd_modes(args: argparse.Namespace) -> int:
    import numpy as np

    from estimator import TABLE1_HZ

    if args.calibration:
        return _print_calibration(args)
    rig = _rig_from_args(args)
    model, freqs, units, unit_of_mode = _plane_modes(rig, args.temperature, args.count)
    # A biaxial beam bends in ξ too: its own frequencies from EI_ξ (a round tube: the same as ζ's).
    xi = _plane_modes(rig, args.temperature, args.count, "xi") if rig.beam.biaxial else None
    # Table 1 is the paper's pinned, hanging sheet: only that configuration is compared with it.
    paper = rig.support == "pinned" and rig.orientation == "hanging"
    table = np.array(TABLE1_HZ)
    n = min(len(freqs), len(table)) if paper else 0
    relative = (freqs[:n] / table[:n] - 1).tolist()
    critical = model.critical_load_factor
    if args.json:
        _print_json({
            "frequencies_hz": [round(float(f), 6) for f in freqs],
            **({"table1_hz": list(TABLE1_HZ), "relative_error": [round(float(r), 6) for r in relative]} if paper else {}),
            "support": rig.support,
            "orientation": rig.orientation,
            "length_m": rig.beam.length,
            "gravity": rig.gravity,
            "critical_load_factor": None if not np.isfinite(critical) else round(float(critical), 6),
            "unit_deformations": [list(group) for group in units.modes],
            **({} if xi is None else _modes_xi_json(xi[0], xi[1], xi[2])),
        })
        return 0
    print(f"{rig.support}, {rig.orientation} beam of {rig.beam.length:g} m, g = {rig.gravity:g} m/s²"
          + (f"; critical load factor {critical:.4g} (it buckles under {critical:.4g} × its weight)" if np.isfinite(critical) else ""))
    if xi is not None:
        _print_biaxial_modes(freqs, unit_of_mode, xi[1], xi[3])
        return 0
    print(f"{'mode':>4} {'f [Hz]':>9}" + (f" {'Table 1':>8} {'error':>8}" if paper else "") + "  unit deformation")
    for k, f in enumerate(freqs, start=1):
        compared = ""
        if paper:
            t = f"{table[k - 1]:8.3f}" if k <= len(table) else " " * 8
            r = f"{100 * relative[k - 1]:+7.2f}%" if k <= n else " " * 8
            compared = f" {t} {r}"
        print(f"{k:4d} {f:9.4f}{compared}  {unit_of_mode.get(k, '-')}")
    return 0


def _modes_xi_json(model, freqs, units) -> dict:
    """The ξ plane's keys of ``shm modes --json`` for a biaxial beam."""
    import numpy as np

    critical = model.critical_load_factor
    return {
        "bending": "biaxial",
        "frequencies_xi_hz": [round(float(f), 6) for f in freqs],
        "critical_load_factor_xi": None if not np.isfinite(critical) else round(float(critical), 6),
        "unit_deformations_xi": [list(group) for group in units.modes],
    }


def _print_biaxial_modes(freqs, unit_of_mode: dict, freqs_xi, unit_of_mode_xi: dict) -> None:
    """Both planes' frequencies side by side, each mode with its plane's unit deformation."""
    print("biaxial: bending in ζ and in ξ")
    print(f"{'mode':>4} {'f ζ [Hz]':>10} {'unit ζ':>6} {'f ξ [Hz]':>10} {'unit ξ':>6}")
    for k, (f, f_xi) in enumerate(zip(freqs, freqs_xi), start=1):
        print(f"{k:4d} {f:10.4f} {unit_of_mode.get(k, '-')!s:>6} {f_xi:10.4f} {unit_of_mode_xi.get(k, '-')!s:>6}")


def _print_calibration(args: argparse.Namespace) -> int:
    """The frozen model update against Table 1 with what the frequencies determine of it."""
    if args.rig or args.layout != "benchmark":
        raise CliError("--calibration describes the shipped calibration of the benchmark layout; drop --rig/--layout")
    from ..rig_layouts import CALIBRATED, CALIBRATION_PARAMETERS, frozen_calibration_identifiability

    ident = frozen_calibration_identifiability()
    if args.json:
        _print_json({"calibration": ident.as_dict()})
        return 0
    nominal = {p.name: p.nominal for p in CALIBRATION_PARAMETERS}
    print(f"Model update of the benchmark layout against Table 1 (frozen values; target σ = {100 * ident.frequency_std:.2f} %"
          f" from the residuals, cost {ident.cost:.4g})")
    print(f"{'parameter':<24} {'nominal':>10} {'calibrated':>11} {'± 1σ':>10} {'prior σ':>10} {'resolution':>10}")
    for name, std, prior, res in zip(ident.names, ident.std, ident.prior_std, ident.resolution):
        flag = "" if name not in ident.undetermined else "  not determined by the frequencies"
        print(f"{name:<24} {nominal[name]:10.4g} {CALIBRATED[name]:11.4g} {std:10.3g} {prior:10.3g} {res:10.3f}{flag}")
    print(f"effective parameters determined: {ident.effective_parameters:.2f} of {len(ident.names)}")
    print("singular values of the weighted relative sensitivities (1 % along a combination moves the weighted frequencies by s %):")
    for i, value in enumerate(ident.singular_values):
        print(f"  s{i + 1} = {value:.3g}: {ident.combination_text(i)}")
    return 0
