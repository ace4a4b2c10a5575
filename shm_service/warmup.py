"""Compile the numba kernels once, when the product is installed, so that the first ``shm serve``
or ``make demo`` shows live estimates at once instead of compiling for a minute or more.

The kernels (the filter's event loop and EKF steps, the recording decoder, the virtual rig's
plant and excitation) are compiled with ``numba.njit(cache=True)``: the first process that calls
one compiles it and writes it to numba's cache (``__pycache__`` next to the module), every later
process loads it in a fraction of a second. :func:`compile_kernels` makes that first call on the
product's own paths (the service on the virtual rig, then the offline estimator over the recording
it wrote), so exactly the specialisations the service uses are cached, and then writes a stamp.
:func:`kernels_ready` reads the stamp: it is keyed by the kernels' sources, numba's and Python's
versions and the CPU, as numba's cache is, so an edit or an upgrade makes the next run compile
again (and say so).

``make`` runs ``python -m shm_service.warmup`` after installing; ``shm serve`` runs the same
compilation itself (and tells the console, ``/api/status`` and the dashboard) when the stamp is
missing or stale.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

__all__ = ["Cancelled", "KERNEL_MODULES", "compile_kernels", "kernels_ready", "stamp_path"]

_ROOT = Path(__file__).resolve().parents[1]
#: Set in the runs that compile: their ``shm serve`` must not wait for the compilation they are.
CHILD_ENV = "SHM_COMPILING_KERNELS"

#: The modules holding ``numba.njit(cache=True)`` kernels, relative to the repository's root.
KERNEL_MODULES = (
    "estimator/_imms.py",
    "estimator/_ekf.py",
    "shm_service/recording/_fastdecode.py",
    "shm_service/virtual_rig/_plant.py",
    "shm_service/virtual_rig/_excitation.py",
)

#: The short run that calls every kernel: rest phase (60 s) and calibration, then 20 s of filtering.
_WARMUP_TOML = """
log_level = "warning"
[sim]
duration_s = 84.0
damage = []
[source]
speed = "max"
[dashboard]
enabled = false
[estimator]
warmup_s = 0.0
[archive]
raw = "always"
estimates = false
"""


def _key() -> str:
    import llvmlite.binding as llvm
    import numba

    h = hashlib.sha256()
    h.update(f"{sys.version}|{numba.__version__}|{llvm.get_host_cpu_name()}".encode())
    for rel in KERNEL_MODULES:
        h.update(rel.encode())
        h.update((_ROOT / rel).read_bytes())
    return h.hexdigest()


def stamp_path() -> Path:
    """Where the stamp lives: beside numba's cache of the filter (``estimator/__pycache__``)."""
    return _ROOT / "estimator" / "__pycache__" / "shm-kernels.stamp"


def kernels_ready() -> bool:
    """Whether :func:`compile_kernels` ran on these kernels' sources with this numba, Python and CPU.

    Examples
    --------
    >>> isinstance(kernels_ready(), bool)
    True
    """
    try:
        return stamp_path().read_text().strip() == _key()
    except OSError:
        return False


@contextlib.contextmanager
def _lock() -> Iterator[None]:
    """One compilation at a time on this checkout (parallel test workers or services wait for it)."""
    path = stamp_path().with_suffix(".lock")
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _end_with_parent() -> None:
    """In the child: the kernel ends it when the thread that started it ends (even by SIGKILL)."""
    from ._lifetime import set_parent_death_signal

    set_parent_death_signal(signal.SIGKILL)


class Cancelled(RuntimeError):
    """The compilation was cancelled (the caller is stopping)."""


def _run(args: list[str], cwd: Path, timeout_s: float, cancel: threading.Event | None) -> None:
    env = {**os.environ, CHILD_ENV: "1", "PYTHONPATH": os.pathsep.join(p for p in (str(_ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    with open(cwd / "out.txt", "w+") as out:
        proc = subprocess.Popen([sys.executable, "-m", "shm_service.cli", *args], cwd=cwd, env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, preexec_fn=_end_with_parent,
                                start_new_session=True)  # a terminal's Ctrl-C reaches it through cancel only
        deadline = time.monotonic() + timeout_s
        try:  # the child never outlives this process's wish to stop
            while proc.poll() is None:
                if cancel is not None and cancel.is_set():
                    raise Cancelled("cancelled")
                if time.monotonic() > deadline:
                    raise RuntimeError(f"shm {args[0]} took longer than {timeout_s:g} s while compiling the kernels")
                time.sleep(0.2)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if proc.returncode != 0:
            out.seek(0)
            raise RuntimeError(f"shm {args[0]} failed while compiling the kernels (exit {proc.returncode}):\n"
                               f"{out.read()[-3000:]}")


def compile_kernels(*, force: bool = False, timeout_s: float = 1800.0, cancel: threading.Event | None = None) -> float:
    """Compile and cache every kernel the service and the offline tools call; returns the seconds taken.

    Runs ``shm serve --source sim`` over 84 simulated seconds at full speed (no dashboard, a
    temporary data directory), then ``shm estimate`` over the raw recording it wrote, each in a
    subprocess, and writes the stamp :func:`kernels_ready` reads. With the stamp current (and not
    ``force``) it returns 0.0 at once. Concurrent callers wait for one another.

    ``cancel`` set ends the runs at once (:class:`Cancelled`; no stamp is written).

    Raises
    ------
    RuntimeError
        When one of the two runs fails (its output's tail in the message) or takes longer than
        ``timeout_s``.
    """
    if not force and kernels_ready():
        return 0.0
    with _lock():
        if not force and kernels_ready():  # another process compiled them meanwhile
            return 0.0
        t0 = time.monotonic()
        with tempfile.TemporaryDirectory(prefix="shm-warmup-") as tmp:
            work = Path(tmp)
            (work / "warmup.toml").write_text(_WARMUP_TOML)
            _run(["serve", "--config", "warmup.toml", "--data-dir", "var", "--port", "0"], work, timeout_s, cancel)
            raw = sorted((work / "var" / "recordings").glob("*.mcap"))
            if not raw:
                raise RuntimeError("shm serve wrote no recording while compiling the kernels")
            _run(["estimate", str(raw[0]), "--json"], work, timeout_s, cancel)
        stamp = stamp_path()
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(_key() + "\n")
        return time.monotonic() - t0


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m shm_service.warmup", description=__doc__.split("\n\n")[0])
    p.add_argument("--force", action="store_true", help="compile even when the stamp is current")
    args = p.parse_args(argv)
    if not args.force and kernels_ready():
        print("shm: the filter's kernels are compiled and cached", flush=True)
        return 0
    print("shm: compiling the filter's kernels once (cached for every later run; about a minute on 2 cores) ...", flush=True)
    try:
        took = compile_kernels(force=args.force)
    except (RuntimeError, OSError, subprocess.TimeoutExpired) as exc:
        print(f"shm: error: {exc}", file=sys.stderr)
        return 1
    print(f"shm: kernels compiled and cached in {took:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
