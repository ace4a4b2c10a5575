"""Throwaway PostgreSQL and Mosquitto servers for the tests and a local demo of a fleet.

Each server runs from a fresh temporary directory on a free loopback port and dies with the
process that started it: its child is given a parent-death signal (``prctl(PR_SET_PDEATHSIG)``,
Linux), so a test run that is killed leaves no server behind; :meth:`DevServer.stop` stops it
cleanly and removes its directory.

PostgreSQL refuses to run as root: when this process is root, ``initdb`` and ``postgres`` run as
the ``postgres`` user (Debian's package creates it) in a directory owned by that user. Mosquitto
runs as its ``mosquitto`` user likewise (started as root, it would drop to it by itself, after the
parent-death signal was set, which that change of user clears).

``python -m shm_service.devservers`` (``make servers``) runs both until Ctrl-C and prints their
URLs; ``--two-nodes`` (``make fleet-demo``) also starts two nodes on a small fleet fed at real time
(shm_service/_fleetdemo.py; docs/operations/index.md, "Running a fleet across machines").
"""

from __future__ import annotations

import argparse
import ctypes
import glob
import os
import pwd
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["DevServer", "ServersMissing", "find_postgres_bin", "free_port", "main", "start_mosquitto", "start_postgres"]

_PR_SET_PDEATHSIG = 1


class ServersMissing(RuntimeError):
    """PostgreSQL or Mosquitto is not installed (the message says which, and how to install it)."""


def free_port() -> int:
    """A TCP port of 127.0.0.1 that is free at this instant (the kernel's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def find_postgres_bin() -> Path:
    """The directory of PostgreSQL's server programs: ``$SHM_POSTGRES_BIN``, else the newest
    ``/usr/lib/postgresql/N/bin`` (Debian's layout), else the directory of ``postgres`` on the PATH.

    Raises
    ------
    ServersMissing
        If none holds ``initdb`` and ``postgres``.
    """
    candidates: list[Path] = []
    if os.environ.get("SHM_POSTGRES_BIN"):
        candidates.append(Path(os.environ["SHM_POSTGRES_BIN"]))
    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(Path(p).parent.name)
                      if Path(p).parent.name.isdigit() else 0, reverse=True)
    candidates += [Path(p) for p in versions]
    on_path = shutil.which("postgres")
    if on_path:
        candidates.append(Path(on_path).parent)
    for c in candidates:
        if (c / "initdb").is_file() and (c / "postgres").is_file():
            return c
    raise ServersMissing(f"PostgreSQL's server programs (initdb, postgres) are not in {[str(c) for c in candidates] or 'any known place'}: "
                         "install Debian's package (`make servers-installed` as root: apt-get install postgresql) "
                         "or set SHM_POSTGRES_BIN")


def _find_mosquitto() -> Path:
    for c in (os.environ.get("SHM_MOSQUITTO"), shutil.which("mosquitto"), "/usr/sbin/mosquitto"):
        if c and Path(c).is_file():
            return Path(c)
    raise ServersMissing("the MQTT broker mosquitto is not installed: install Debian's package "
                         "(`make servers-installed` as root: apt-get install mosquitto) or set SHM_MOSQUITTO")


def _as_user(user: str | None, death_signal: int) -> Callable[[], None]:
    """A ``preexec_fn``: become ``user`` (when given) and then ask the kernel for ``death_signal``
    when the parent dies (after the change of user, which would clear it)."""
    account = pwd.getpwnam(user) if user else None

    def run() -> None:
        os.setsid()  # its own process group: a Ctrl-C of the terminal reaches the parent only, who stops it cleanly
        if account is not None:
            os.initgroups(account.pw_name, account.pw_gid)
            os.setgid(account.pw_gid)
            os.setuid(account.pw_uid)
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, death_signal, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG)")
        if os.getppid() == 1:  # the parent died before the prctl
            os.kill(os.getpid(), death_signal)

    return run


@dataclass
class DevServer:
    """A running throwaway server: its process, address, directory and log."""

    name: str
    process: subprocess.Popen
    host: str
    port: int
    url: str
    directory: Path
    log: Path
    stop_signal: int = signal.SIGTERM
    _stopped: bool = field(default=False, repr=False)

    def alive(self) -> bool:
        return self.process.poll() is None

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""

    def stop(self, timeout_s: float = 15.0) -> None:
        """Stop the server (``stop_signal``, then SIGKILL after ``timeout_s``) and remove its directory."""
        if self._stopped:
            return
        self._stopped = True
        if self.process.poll() is None:
            self.process.send_signal(self.stop_signal)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        shutil.rmtree(self.directory, ignore_errors=True)

    def __enter__(self) -> "DevServer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _wait_port(server: DevServer, timeout_s: float, ready: Callable[[], bool] | None = None) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not server.alive():
            tail = server.log_tail()
            server.stop()  # removes its directory
            raise RuntimeError(f"{server.name} exited with code {server.process.returncode} while starting:\n{tail}")
        try:
            with socket.create_connection((server.host, server.port), timeout=0.5):
                if ready is None or ready():
                    return
        except OSError:
            pass
        time.sleep(0.05)
    tail = server.log_tail()
    server.stop()
    raise RuntimeError(f"{server.name} did not listen on {server.host}:{server.port} within {timeout_s:g} s:\n{tail}")


_OWNER = "started-by.pid"


def _make_directory(prefix: str, parent: str | Path | None) -> Path:
    """A fresh temporary directory naming the process that made it; the directories of earlier
    processes of the same prefix that are gone (killed before they could remove them) are removed."""
    base = Path(parent) if parent is not None else Path(tempfile.gettempdir())
    for old in base.glob(f"{prefix}*"):
        try:
            pid = int((old / _OWNER).read_text().strip())
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(old, ignore_errors=True)
        except (OSError, ValueError):
            continue  # not ours to judge (no record, or another user's process)
    directory = Path(tempfile.mkdtemp(prefix=prefix, dir=base))
    (directory / _OWNER).write_text(f"{os.getpid()}\n")
    return directory


def _run_user() -> str | None:
    """The user the servers run as: ``postgres`` when this process is root, else this user."""
    if os.geteuid() != 0:
        return None
    try:
        pwd.getpwnam("postgres")
    except KeyError:
        raise ServersMissing("running as root and there is no 'postgres' user to run PostgreSQL as "
                             "(Debian's postgresql package creates it)") from None
    return "postgres"


def start_postgres(*, port: int | None = None, database: str = "shm", durable: bool = False,
                   timeout_s: float = 60.0, parent: str | Path | None = None) -> DevServer:
    """Start a throwaway PostgreSQL on 127.0.0.1 with one database ``database`` and trust
    authentication for its superuser ``postgres``; ``url`` is ``postgresql://postgres@127.0.0.1:PORT/DB``.

    Parameters
    ----------
    port
        The TCP port (default: a free one).
    database
        The database created in it.
    durable
        ``fsync`` on (off by default: a throwaway cluster survives a crash of its processes, not
        of the machine, and the tests run several times faster).
    timeout_s
        How long the start may take.
    parent
        Where its temporary directory is made (default: the system's).
    """
    bindir = find_postgres_bin()
    user = _run_user()
    directory = _make_directory("shm-postgres-", parent)
    data, sockets, log = directory / "data", directory / "sock", directory / "postgres.log"
    sockets.mkdir()
    if user is not None:
        account = pwd.getpwnam(user)
        for p in (directory, sockets):
            os.chown(p, account.pw_uid, account.pw_gid)
    preexec = _as_user(user, signal.SIGQUIT)
    init = subprocess.run([str(bindir / "initdb"), "-D", str(data), "-U", "postgres", "--auth=trust", "-E", "UTF8",
                           "--locale=C", "--no-sync"], preexec_fn=preexec, capture_output=True, text=True, cwd=directory)
    if init.returncode != 0:
        shutil.rmtree(directory, ignore_errors=True)
        raise RuntimeError(f"initdb failed ({init.returncode}): {init.stderr.strip() or init.stdout.strip()}")
    port = free_port() if port is None else int(port)
    settings = {"listen_addresses": "127.0.0.1", "port": str(port), "unix_socket_directories": str(sockets),
                "fsync": "on" if durable else "off", "synchronous_commit": "on" if durable else "off",
                "full_page_writes": "on" if durable else "off", "max_connections": "200", "logging_collector": "off"}
    args = [str(bindir / "postgres"), "-D", str(data)] + [a for k, v in settings.items() for a in ("-c", f"{k}={v}")]
    with open(log, "ab") as out:
        # SIGQUIT on the parent's death: an immediate shutdown (the backends end with the postmaster)
        process = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                   preexec_fn=preexec, cwd=directory)
    url = f"postgresql://postgres@127.0.0.1:{port}/{database}"
    server = DevServer("postgres", process, "127.0.0.1", port, url, directory, log, stop_signal=signal.SIGINT)
    psql = str(bindir / "psql")

    def accepting() -> bool:  # this server, not another one on the port
        probe = subprocess.run([psql, "-h", "127.0.0.1", "-p", str(port), "-U", "postgres", "-d", "postgres", "-Atc",
                                "SHOW data_directory"], capture_output=True, text=True)
        return probe.returncode == 0 and probe.stdout.strip() == str(data)

    _wait_port(server, timeout_s, accepting)
    made = subprocess.run([psql, "-h", "127.0.0.1", "-p", str(port), "-U", "postgres", "-d", "postgres", "-Atc",
                           f'CREATE DATABASE "{database}"'], capture_output=True, text=True)
    if made.returncode != 0:
        server.stop()
        raise RuntimeError(f"CREATE DATABASE {database} failed: {made.stderr.strip()}")
    return server


def start_mosquitto(*, port: int | None = None, timeout_s: float = 30.0, parent: str | Path | None = None,
                    extra_config: Sequence[str] = ()) -> DevServer:
    """Start a throwaway Mosquitto on 127.0.0.1 (anonymous clients allowed, persistence in its
    directory, no bound on a session's queue); ``url`` is ``mqtt://127.0.0.1:PORT``.

    Parameters
    ----------
    port
        The TCP port (default: a free one).
    timeout_s
        How long the start may take.
    parent
        Where its temporary directory is made (default: the system's).
    extra_config
        Lines appended to its configuration (users, TLS listeners).
    """
    binary = _find_mosquitto()
    directory = _make_directory("shm-mosquitto-", parent)
    port = free_port() if port is None else int(port)
    log = directory / "mosquitto.log"
    lines = [f"listener {port} 127.0.0.1", "allow_anonymous true", "persistence true",
             f"persistence_location {directory}/", "autosave_interval 5",
             # a session kept for a structure no node holds keeps every message (the default drops past 1000)
             "max_queued_messages 0", "max_queued_bytes 0", "max_inflight_messages 100",
             "log_dest stdout", "log_type error", "log_type warning", "log_type notice", *extra_config]
    config = directory / "mosquitto.conf"
    config.write_text("\n".join(lines) + "\n")
    user = None
    if os.geteuid() == 0:
        # run as its own user from the start: mosquitto would drop to it after exec itself, and that
        # change of user clears the parent-death signal
        try:
            account = pwd.getpwnam("mosquitto")
            user = "mosquitto"
            for p in (directory, config):
                os.chown(p, account.pw_uid, account.pw_gid)
        except KeyError:
            config.write_text("\n".join([*lines, "user root"]) + "\n")
    with open(log, "ab") as out:
        process = subprocess.Popen([str(binary), "-c", str(config)], stdout=out, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, preexec_fn=_as_user(user, signal.SIGTERM), cwd=directory)
    server = DevServer("mosquitto", process, "127.0.0.1", port, f"mqtt://127.0.0.1:{port}", directory, log)
    _wait_port(server, timeout_s, lambda: _mqtt_answers(port) and server.alive())
    return server


def _mqtt_answers(port: int) -> bool:
    """Whether an MQTT broker answers a CONNECT (3.1.1, clean session, empty client id) on ``port``
    with a CONNACK that accepts it: this broker, not another server on the port."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=2.0) as s:
            s.sendall(bytes([0x10, 12, 0, 4]) + b"MQTT" + bytes([4, 0x02, 0, 60, 0, 0]))
            answer = s.recv(4)
            s.sendall(bytes([0xE0, 0]))  # DISCONNECT
    except OSError:
        return False
    return answer == bytes([0x20, 2, 0, 0])


def main(argv: Sequence[str] | None = None) -> int:
    """Run both servers until Ctrl-C (``make servers``): the URLs to put in a fleet's configuration."""
    parser = argparse.ArgumentParser(prog="python -m shm_service.devservers", description=__doc__.split("\n\n")[0])
    parser.add_argument("--postgres-port", type=int, default=None, help="PostgreSQL's port (default: a free one)")
    parser.add_argument("--mqtt-port", type=int, default=None, help="Mosquitto's port (default: a free one)")
    parser.add_argument("--two-nodes", action="store_true",
                        help="also two nodes (shm serve --node a|b) on a small fleet of mqtt structures fed at real time")
    parser.add_argument("--structures", type=int, default=4, help="with --two-nodes: the fleet's structures (default 4)")
    args = parser.parse_args(argv)
    if args.two_nodes:
        from ._fleetdemo import run_two_nodes

        return run_two_nodes(start_postgres, start_mosquitto, args.structures)
    postgres = start_postgres(port=args.postgres_port)
    try:
        mqtt = start_mosquitto(port=args.mqtt_port)
    except BaseException:
        postgres.stop()
        raise
    print(f"PostgreSQL: {postgres.url}   (log {postgres.log})")
    print(f"Mosquitto:  {mqtt.url}   (log {mqtt.log})")
    print("In a fleet's configuration:\n"
          f'  [storage]\n  url = "{postgres.url}"\n  [mqtt]\n  url = "{mqtt.url}"')
    print("Ctrl-C stops both (their data go with them).", flush=True)
    stop = False

    def on_signal(signum: int, frame: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_signal)
    try:
        while not stop:
            for s in (postgres, mqtt):
                if not s.alive():
                    print(f"{s.name} exited ({s.process.returncode}):\n{s.log_tail()}", file=sys.stderr)
                    return 1
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        mqtt.stop()
        postgres.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
