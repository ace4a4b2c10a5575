"""One way to start ``shm serve`` (or ``shm demo``) as a child process: the fleet's front starts its
workers with it, the tests and the benchmarks their services.

The child writes its ready document (``--ready-file``, see ``runtime._processes``) once its API answers;
the child ends with the process that started it (``--parent-pid``), however that one ends.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from ._processes import child_environ, read_ready

__all__ = ["ServeProcess", "ServeStartError", "start_serve"]


class ServeStartError(RuntimeError):
    """The process ended, or did not say it was ready in time."""


class ServeProcess:
    """A started ``shm serve``: its ``subprocess.Popen`` and its ready document."""

    def __init__(self, process: subprocess.Popen[Any], ready_file: Path, what: str, owns_dir: Path | None) -> None:
        self.process = process
        self.ready_file = ready_file
        self.what = what
        self.ready: dict[str, Any] = {}
        self._owns_dir = owns_dir

    @property
    def pid(self) -> int:
        return int(self.process.pid)

    @property
    def url(self) -> str:
        """The API's base URL (``http://host:port``)."""
        return str(self.ready["api"])

    @property
    def dashboard_url(self) -> str | None:
        value = self.ready.get("dashboard")
        return None if value is None else str(value)

    def wait_ready(self, timeout: float = 120.0, until: Callable[[dict[str, Any]], bool] | None = None,
                   poll_s: float = 0.05) -> dict[str, Any]:
        """Wait for the ready document (and, with ``until``, for one it accepts); returns it.

        Raises
        ------
        ServeStartError
            The process ended first (with its exit code) or ``timeout`` passed.
        """
        deadline = time.monotonic() + timeout
        while True:
            doc = read_ready(self.ready_file)
            if doc is not None and (until is None or until(doc)):
                self.ready = doc
                return doc
            code = self.process.poll()
            if code is not None:
                raise ServeStartError(f"{self.what} ended with exit code {code} before it was ready")
            if time.monotonic() >= deadline:
                raise ServeStartError(f"{self.what} was not ready within {timeout:g} s (last document: {doc})")
            time.sleep(poll_s)

    def stop(self, timeout: float = 60.0) -> int:
        """SIGTERM (it drains and prints its summary), SIGKILL after ``timeout``; the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(10)
        self._cleanup()
        return int(self.process.returncode)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(10)
        self._cleanup()

    def _cleanup(self) -> None:
        if self._owns_dir is not None:
            for path in self._owns_dir.iterdir():
                path.unlink(missing_ok=True)
            self._owns_dir.rmdir()
            self._owns_dir = None

    def __enter__(self) -> ServeProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def start_serve(args: Sequence[str] = (), *, command: str = "serve", env: Mapping[str, str] | None = None,
                cwd: str | os.PathLike[str] | None = None, stdout: int | IO[Any] | None = None,
                stderr: int | IO[Any] | None = None, text: bool = True, ready_file: str | os.PathLike[str] | None = None,
                timeout: float | None = 120.0, until: Callable[[dict[str, Any]], bool] | None = None,
                start_new_session: bool = False, python: str | None = None) -> ServeProcess:
    """Start ``shm <command> ARGS`` (``serve`` or ``demo``) as a child that ends with this process,
    and wait (unless ``timeout`` is None) until its ready document says its API answers.

    Parameters
    ----------
    args : sequence of str
        The command's arguments (``--config``, ``--port 0``, ...).
    command : {"serve", "demo"}
    env, cwd, stdout, stderr, text, start_new_session
        As for ``subprocess.Popen`` (``env`` defaults to this process's environment).
    ready_file : path, optional
        Where the child writes its ready document (default: a fresh temporary directory's file).
    timeout : float or None
        Seconds to wait for readiness; None: return at once (call ``wait_ready`` later).
    until : callable, optional
        Wait for a ready document it accepts (e.g. one with the dashboard's address).

    Raises
    ------
    ValueError
        ``command`` is neither ``serve`` nor ``demo``.
    ServeStartError
        As ``ServeProcess.wait_ready``; the process is killed.
    """
    if command not in ("serve", "demo"):
        raise ValueError(f"command {command!r} must be 'serve' or 'demo'")
    owns = None
    if ready_file is None:
        owns = Path(tempfile.mkdtemp(prefix="shm-ready-"))
        ready = owns / "ready.json"
    else:
        ready = Path(ready_file)
        ready.unlink(missing_ok=True)
    cmd = [python or sys.executable, "-m", "shm_service.cli", command, *args, "--ready-file", str(ready),
           "--parent-pid", str(os.getpid())]
    process = subprocess.Popen(cmd, cwd=cwd, env=child_environ(env), stdout=stdout, stderr=stderr, text=text,
                               start_new_session=start_new_session)
    started = ServeProcess(process, ready, f"shm {command} (pid {process.pid})", owns)
    if timeout is not None:
        try:
            started.wait_ready(timeout, until)
        except BaseException:
            started.kill()
            raise
    return started
