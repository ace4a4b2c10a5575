"""The CPU of a live fleet, process by process, for two trees in alternating order (a benchmark,
not a test).

``bench_fleet --compare`` measures the whole budget (lag, RSS, CPU per structure-second) over
10-minute runs. This is the quick A/B for a change in the runtime: ``shm serve`` of ``--structures``
simulated structures on two worker processes (``--no-archive``, real time, 2 s blocks), the CPU
of the front and of each worker over ``--measure-s`` once ``--skip-s`` have passed since its API
came up (the start, the
kernels, the first windows), for each tree in turn, ``--rounds`` times::

    git worktree add ../other <commit>
    python -m benchmarks.fleet_cpu --tree ../other --tree . --rounds 2

Prints one line per run and the mean cores per tree. A tree's kernels compile on its first run
there; run once before measuring.
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from benchmarks.bench_fleet import _fleet_toml, _load, _start_tree_serve


def fleet_cpu(tree: Path, structures: int, *, skip_s: float, measure_s: float) -> dict:
    """Cores used by the front and by each worker of ``tree``'s ``shm serve`` of ``structures``
    simulated structures on two workers, over ``measure_s`` from ``skip_s`` after its API came up."""
    import psutil

    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "fleet.toml"
        cfg.write_text(_fleet_toml([f"m{k:03d}" for k in range(structures)], 2.0, 3600.0), encoding="utf-8")
        args = ["--config", str(cfg), "--speed", "1", "--no-archive", "--port", "0", "--db", f"{tmp}/shm.sqlite",
                "--workers", "2", "--json", "--no-dashboard"]
        with open(Path(tmp) / "serve.log", "w") as log:
            proc, _ = _start_tree_serve(tree, args, log, Path(tmp))  # returns once its API is up
            try:
                front = psutil.Process(proc.pid)
                time.sleep(skip_s)
                if proc.poll() is not None:
                    raise RuntimeError(f"{tree}: shm serve ended: {(Path(tmp) / 'serve.log').read_text()[-2000:]}")

                def cpu() -> dict[int, tuple[str, float]]:
                    out = {}
                    for q in [front, *front.children(recursive=True)]:
                        t = q.cpu_times()
                        out[q.pid] = ("front" if q.pid == front.pid else "worker", t.user + t.system)
                    return out

                load = _load()
                a, t0 = cpu(), time.monotonic()
                time.sleep(measure_s)
                b, wall = cpu(), time.monotonic() - t0
            finally:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(90)
                except subprocess.TimeoutExpired:
                    proc.kill()
    cores = {f"{role}-{pid}": round((c - a.get(pid, (role, 0.0))[1]) / wall, 3) for pid, (role, c) in b.items()}
    return {"tree": str(tree), "structures": structures, "cores": cores, "total_cores": round(sum(cores.values()), 3),
            "load": load}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tree", action="append", type=Path, required=True, help="a checkout to run (give two)")
    p.add_argument("--structures", type=int, default=100)
    p.add_argument("--skip-s", type=float, default=200.0)
    p.add_argument("--measure-s", type=float, default=100.0)
    p.add_argument("--rounds", type=int, default=2)
    a = p.parse_args(argv)
    if a.structures < 2 or a.skip_s < 0 or a.measure_s <= 0 or a.rounds < 1:
        p.error("--structures >= 2, --skip-s >= 0, --measure-s > 0 and --rounds >= 1")
    totals: dict[str, list[float]] = {}
    for _ in range(a.rounds):
        for tree in a.tree:
            r = fleet_cpu(tree.resolve(), a.structures, skip_s=a.skip_s, measure_s=a.measure_s)
            print(f"[fleet_cpu] {r}", flush=True)
            totals.setdefault(r["tree"], []).append(r["total_cores"])
    for tree, runs in totals.items():
        print(f"[fleet_cpu] {tree}: {' '.join(f'{x:.3f}' for x in runs)} cores (mean {sum(runs) / len(runs):.3f})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
