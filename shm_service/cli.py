"""The ``shm`` command line: modes, simulate, inspect, estimate, analyze, reprocess, baseline, oma, study, serve,
demo, import, loads.

This module only parses the arguments and dispatches: each command's work is in
``shm_service.commands`` (``shm serve``'s in ``shm_service.service``). Building the parser imports
nothing heavy (numpy, scipy, pydantic, the estimator are imported by the command that needs them,
and a command's module only when it runs), so ``shm --help`` and argument errors answer at once.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable
from typing import Any, Sequence

from ._argtypes import number, output_path
from .commands._common import CliError, add_model_arguments

__all__ = ["main"]


def _command(name: str) -> Callable[[argparse.Namespace], int]:
    """The command ``shm_service.commands.<module>.<function>`` of ``name`` (``"module:function"``),
    imported when it runs."""
    module, function = name.split(":")

    def run(args: argparse.Namespace) -> int:
        implementation: Callable[[argparse.Namespace], int] = getattr(
            importlib.import_module(f"shm_service.commands.{module}"), function)
        return implementation(args)

    return run


def _time_arg(text: str) -> float:
    """UNIX seconds or an ISO 8601 time (UTC unless it says otherwise)."""
    from datetime import datetime, timezone

    try:
        return float(text)
    except ValueError:
        pass
    try:
        moment = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither UNIX seconds nor an ISO 8601 time") from None
    return (moment if moment.tzinfo else moment.replace(tzinfo=timezone.utc)).timestamp()


def _database_target(text: str) -> str:
    """An argparse ``type`` for the service's database: a PostgreSQL URL (checked for a host and
    a database) or a SQLite file (as ``output_path``)."""
    from .service.storage._url import check_postgres_url, is_postgres_url

    if is_postgres_url(text) or "://" in text:
        try:
            return check_postgres_url(text, "--db")
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    return output_path(text)


def _add_analysis_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", default=None, help="a `shm serve` configuration (TOML): the same analytics, alarm hysteresis and warm-up")
    add_model_arguments(p, aided=False)


def _add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=number(int, low=1, high=512), default=None, metavar="N",
                   help="worker processes of the local cluster (default: the cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing dask.distributed scheduler (tcp://host:8786) instead of a local cluster; its "
                        "workers need this package and the files at the same paths")


def _add_configuration_arguments(p: argparse.ArgumentParser, *, rig_file: bool) -> None:
    """--support, --orientation and --length of a layout's rig (the contract's keys)."""
    over = " (overrides the --rig file's key)" if rig_file else ""
    p.add_argument("--support", choices=("pinned", "clamped"), default=None,
                   help=f"pinned: the plain bearing (default); clamped: the fixed bearing, φ ≡ 0{over}")
    p.add_argument("--orientation", choices=("hanging", "standing"), default=None,
                   help=f"hanging below D (default) or standing above it, a mast (needs --support clamped){over}")
    p.add_argument("--length", type=number(low=0, low_open=True, high=1000, unit="m"), default=None, metavar="M",
                   help="beam length in m (default 4); the layout's sensors and truth stations scale with it")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="shm", description="Structural health monitoring by integrated motion measurement.")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_modes_parser(sub)
    _add_simulate_parser(sub)
    _add_estimate_parser(sub)
    _add_study_parser(sub)
    _add_analyze_parser(sub)
    _add_reprocess_parser(sub)
    _add_baseline_parser(sub)
    _add_oma_parser(sub)
    _add_inspect_parser(sub)
    from .commands.demo import add_demo_parser
    from .commands.loads import add_loads_parser  # shm loads
    from .service._cli import add_serve_parser  # shm serve
    add_serve_parser(sub)
    add_demo_parser(sub)
    add_loads_parser(sub)
    _add_import_parser(sub)
    return parser


def _add_modes_parser(sub: Any) -> None:
    p = sub.add_parser("modes", help="eigenfrequencies of the rig model (against the paper's Table 1 when pinned and hanging)")
    p.add_argument("--rig", help="rig description (.json or .toml); default: the calibrated rig of --layout")
    p.add_argument("--layout", choices=("benchmark", "dense"), default="benchmark")
    _add_configuration_arguments(p, rig_file=True)
    p.add_argument("--temperature", type=number(low=-60, high=150, unit="°C"), default=None,
                   help="°C, -60 to 150 (default: the beam's reference temperature)")
    p.add_argument("--count", type=number(int, low=1, high=20), default=6, metavar="N", help="modes to list (1-20)")
    p.add_argument("--calibration", action="store_true",
                   help="the shipped model update against Table 1: each parameter's value, 1σ and resolution "
                        "(what the six frequencies determine), and the identifiable combinations")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("modes:cmd_modes"))


def _add_simulate_parser(sub: Any) -> None:
    p = sub.add_parser("simulate", help="simulate the virtual rig and write a recording")
    p.add_argument("--duration", type=number(low=0, low_open=True, high=7 * 24 * 3600, unit="s"), default=300.0,
                   help="s, up to a week (default 300)")
    p.add_argument("--seed", type=number(int, low=0), default=1)
    p.add_argument("--plant-seed", type=number(int, low=0), default=None, metavar="SEED",
                   help="seed of the structure as built (E and masses a few per cent off the rig file; default --seed): "
                        "a baseline and later recordings of the same structure share it")
    p.add_argument("--out", required=True, type=output_path, help="output .mcap (its directory must exist)")
    p.add_argument("--excitation", choices=("paper", "ambient", "decay", "operational"), default="paper",
                   help="paper: the paper's bearing moves and sine bursts; ambient: random loads, the bearing still; decay: "
                        "plucks and free decays; operational: the support moving randomly (3 mm RMS, broadband) and a "
                        "spatially correlated random load along the beam")
    p.add_argument("--layout", choices=("benchmark", "dense"), default="benchmark")
    p.add_argument("--rig", help="simulate this rig description (.json or .toml) instead of a --layout: any beam, with the "
                                 "sensors it has (no bearing sensor: the support is fixed to the ground); its 'simulator' "
                                 "key may hold settings, which the options given here override")
    _add_configuration_arguments(p, rig_file=True)
    p.add_argument("--wind-load", type=number(low=0, high=1e6, unit="N/m"), default=None, metavar="N/m",
                   help="RMS of the ambient (wind) load along the beam for the ambient and operational excitations, "
                        "N/m (default: 0.05 for the built-in sheet; for a --rig the load whose quasi-static RMS strain "
                        "at the support is 50 µε, about 10 MPa on steel)")
    p.add_argument("--wind-correlation", type=number(low=0, low_open=True, high=1e4, unit="m"), default=None, metavar="M",
                   help="correlation length of the wind load along the beam, m (default 1; a quarter of a --rig beam)")
    p.add_argument("--ideal", action="store_true", help="plant = nominal rig (no mismatch, friction, scale/misalignment)")
    p.add_argument("--damage", action="append", metavar="SPEC", help="mass:KG@POS or stiffness:FACTOR@A-B (repeatable)")
    p.add_argument("--damage-at", type=number(low=0, unit="s"), default=None, metavar="SECONDS",
                   help="damage appears at this time (within --duration)")
    p.add_argument("--temperature-swing", type=number(low=0, high=100, unit="K"), default=0.0, metavar="K",
                   help="peak-to-peak swing, 0-100 K")
    p.add_argument("--temperature-mean", type=number(low=-60, high=150, unit="°C"), default=20.0, metavar="C",
                   help="°C, -60 to 150 (default 20)")
    p.add_argument("--friction", type=number(low=0, high=10, unit="N·m"), default=0.0, metavar="N·m",
                   help="Coulomb friction torque of the bearing (default 0; the study uses 0.03): makes the modal "
                        "figures amplitude dependent, so the recording's exact linear modal figures no longer hold")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("simulate:cmd_simulate"))


def _add_estimate_parser(sub: Any) -> None:
    p = sub.add_parser("estimate", help="run the IMMS estimator over a recording")
    p.add_argument("recording")
    add_model_arguments(p)
    p.add_argument("--out", type=output_path, help="write the estimates to this .mcap (its directory must exist)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("estimate:cmd_estimate"))


def _add_study_parser(sub: Any) -> None:
    p = sub.add_parser("study", help="the paper's sensor-configuration study; design mode with --target-*")
    p.add_argument("--out", default="study", help="output folder (default study/)")
    p.add_argument("--seeds", default=None, help="seeds, one simulated recording each (default 1,2,3)")
    p.add_argument("--duration", type=number(low=0, low_open=True, high=3600, unit="s"), default=None,
                   help="recording length, s, up to 3600 (default 300)")
    p.add_argument("--rest", type=number(low=5, unit="s"), default=None, help="initial rest phase, s, at least 5 (default 60)")
    p.add_argument("--tofs", default=None, help="ν_ρ swept, e.g. 4-13 (default)")
    p.add_argument("--rig", default=None, metavar="FILE",
                   help="study this rig description (.json/.toml) instead of the paper's dense layout, under its "
                        "ambient wind: the sweeps keep the sensor counts it has (no ToFs: ν_ρ = 0)")
    p.add_argument("--modes", type=number(int, low=1, high=5), default=None, metavar="Γ",
                   help="unit deformations Γ (default 4, the paper's; another Γ needs --rig)")
    p.add_argument("--ideal", action="store_true", help="idealised plant (the drift without gauges disappears)")
    p.add_argument("--quick", action="store_true", help="small study: 2 seeds of 240 s, ν_ρ = 4, 5, ν_ε = 0, 2, 4")
    p.add_argument("--workers", type=number(int, low=1, high=64), default=None, help="worker processes, 1-64 (default: the cores)")
    p.add_argument("--keep-recordings", action="store_true", help="keep the simulated recordings in OUT/recordings/")
    p.add_argument("--target-phi-deg", type=number(low=0, low_open=True, high=90, unit="°"), default=None, metavar="X",
                   help="design mode: RMSE target of φ, degrees (0-90]")
    p.add_argument("--target-e-m", type=number(low=0, low_open=True, high=4, unit="m"), default=None, metavar="Y",
                   help="design mode: RMSE target of e, m (0-4]")
    p.set_defaults(func=_command("study:cmd_study"))


def _add_analyze_parser(sub: Any) -> None:
    p = sub.add_parser("analyze", help="modal analytics of the deformation variables (runs the estimator on raw recordings)")
    p.add_argument("recording", help="an estimates recording (shm estimate --out, shm serve's archive) or a raw recording")
    p.add_argument("--baseline", help="a healthy recording to learn the baseline from (all of it; with or without a temperature swing)")
    p.add_argument("--not-before", type=number(low=0, unit="s"), default=None, metavar="S",
                   help="analyse windows starting at or after S seconds into the recording (default: the rest phase's end plus "
                        "the warm-up, when the recording tells the rest phase)")
    _add_analysis_arguments(p)  # the same as reprocess and baseline learn take
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("analyze:cmd_analyze"))


def _add_reprocess_parser(sub: Any) -> None:
    p = sub.add_parser("reprocess", help="estimator and analysis over many recordings (dask.distributed) into a service database")
    p.add_argument("recordings", nargs="+", metavar="FILE", help="recordings (.mcap) of the contract")
    p.add_argument("--db", required=True, type=_database_target,
                   help="the service's database: a SQLite file (created if missing) or postgresql://USER@HOST:PORT/DB")
    _add_cluster_arguments(p)
    p.add_argument("--force", action="store_true", help="reprocess files already done with this configuration")
    p.add_argument("--structure", default=None, metavar="ID",
                   help="source id of the rows (default: an archive file's source, else the file's stem)")
    _add_analysis_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("reprocess:cmd_reprocess"))


def _add_baseline_parser(sub: Any) -> None:
    p = sub.add_parser("baseline", help="baselines of the live service")
    baseline_sub = p.add_subparsers(dest="baseline_command", required=True)
    p = baseline_sub.add_parser("learn", help="learn a baseline from a healthy period spread over recordings and store "
                                              "it as the structure's active baseline (the service loads it at start)")
    p.add_argument("recordings", nargs="+", metavar="FILE", help="recordings (.mcap) of the healthy period")
    p.add_argument("--structure", required=True, metavar="ID", help="the source id the service monitors it as")
    p.add_argument("--db", required=True, type=_database_target,
                   help="the service's database: a SQLite file or postgresql://USER@HOST:PORT/DB")
    p.add_argument("--from", dest="start", type=_time_arg, default=None, metavar="TIME",
                   help="start of the healthy period: UNIX s or ISO 8601 (default: the files' start)")
    p.add_argument("--to", dest="end", type=_time_arg, default=None, metavar="TIME",
                   help="end of the healthy period (default: the files' end)")
    _add_cluster_arguments(p)
    _add_analysis_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("reprocess:cmd_baseline_learn"))


def _add_oma_parser(sub: Any) -> None:
    p = sub.add_parser("oma", help="operational modal analysis (SSI-cov) of measured channels: .npy/.npz, CSV/TSV/text, .mat, HDF5, .mcap")
    p.add_argument("data", help="measured channels (see shm_service/formats/tables.py for the formats)")
    p.add_argument("--fs", type=number(low=0, low_open=True, unit="Hz"), default=None,
                   help="sample rate, Hz (required without a time column)")
    p.add_argument("--channels", default=None, help="channels to use, names or column indices: A,B,...")
    p.add_argument("--fmin", type=number(low=0, unit="Hz"), default=None, help="lower edge of the analysed band, Hz")
    p.add_argument("--fmax", type=number(low=0, low_open=True, unit="Hz"), default=None,
                   help="upper edge of the analysed band, Hz (default 0.4·fs)")
    p.add_argument("--inputs", default=None, help="measured input channels (support acceleration): FRF cross-check and excitation class")
    p.add_argument("--window", type=number(low=0, low_open=True, unit="s"), default=None, metavar="S",
                   help="also identify windows of S seconds")
    p.add_argument("--step", type=number(low=0, low_open=True, unit="s"), default=None, metavar="S",
                   help="window step, s (default: --window)")
    p.add_argument("--max-abs", type=number(low=0, low_open=True), default=None, metavar="X",
                   help="reject |value| > X (the file's units) as implausible")
    p.add_argument("--outlier-factor", type=number(low=0), default=1000.0, metavar="F",
                   help="reject |x - median| > F x the channel's 90th percentile of |x - median| as implausible (0: off) [1000]")
    p.add_argument("--max-fill", type=int, default=4, metavar="N",
                   help="fill runs of at most N rejected samples by linear interpolation; longer gaps: the longest valid span [4]")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("oma:cmd_oma"))


def _add_inspect_parser(sub: Any) -> None:
    p = sub.add_parser("inspect", help="topics, counts, rates, gaps and problems of a recording")
    p.add_argument("recording")
    p.add_argument("--rig", help="rig description to use instead of the attached rig.json")
    p.add_argument("--json", action="store_true")
    p.add_argument("--print-rig", action="store_true", help="print the recording's rig description (rig.json) and exit")
    p.set_defaults(func=_command("inspection:cmd_inspect"))


def _add_import_parser(sub: Any) -> None:
    p = sub.add_parser(
        "import",
        help="measured channels of DAQ files (CSV/TSV/text, LabVIEW, .npy/.npz, .mat, HDF5) into a contract recording",
    )
    p.add_argument("data", nargs="+", help="the DAQ file(s); several when the map's clocks read different files")
    p.add_argument("--rig", required=True, help="rig description (.json or .toml) declaring every topic of the map")
    p.add_argument("--map", required=True, help="channel map (.toml): per column topic, field, index, scale, offset, clock")
    p.add_argument("--out", required=True, type=output_path, help="the recording to write (.mcap; its directory must exist)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_command("daq:cmd_import"))


def _user_errors() -> tuple[type[BaseException], ...]:
    """Errors that are the user's (bad file, bad rig): the modules defining them are imported only
    when a command has already loaded them."""
    errors: list[type[BaseException]] = [CliError, FileNotFoundError]
    if "contract._rig" in sys.modules:
        errors.append(sys.modules["contract._rig"].RigError)
    if "shm_service.recording._reader" in sys.modules:
        errors.append(sys.modules["shm_service.recording._reader"].RecordingError)
    return tuple(errors)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or an argument error (2, already printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        code = args.func(args)
        sys.stdout.flush()  # a reader that went away (``| head``) answers here, not in the flush at exit
        return code
    except BrokenPipeError:
        if not _stdout_closed():
            raise  # another pipe of the command's: its own error
        return _stdout_gone()
    except Exception as exc:
        if not isinstance(exc, _user_errors()):
            raise
        print(f"shm {args.command}: error: {exc}", file=sys.stderr)
        return 2


#: The exit status of a writer whose reader closed the pipe (the shell's 128 + SIGPIPE).
EXIT_BROKEN_PIPE = 141


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has gone (poll reports an error on its write end)."""
    import select

    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (AttributeError, OSError, ValueError):
        return True  # no file descriptor to ask: the error was raised writing to it


def _stdout_gone() -> int:
    """What Python's documentation advises for SIGPIPE: stdout pointed at devnull, so the flush at
    exit does not raise again, and a quiet exit with the shell's status of a closed pipe."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):
        pass
    return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
