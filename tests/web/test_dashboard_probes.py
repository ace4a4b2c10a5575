"""A client that opens the dashboard's port and closes it without a request (a browser's
preconnect, a TCP health check) is not an error in the service's log; a client that sends
something that is not a handshake still is. A real viser server and real sockets."""

from __future__ import annotations

import logging
import socket

import pytest
import viser
from browser_helpers import wait

from web._dashboard import _PROBES


@pytest.fixture()
def viser_server():
    # viser adds a filter of its own that drops every "opening handshake failed" once a server of
    # the process has answered its first HTTP request (earlier tests' servers did): the logger with
    # ours alone, as in a service whose dashboard has not been asked for its page yet
    logger = logging.getLogger("websockets.server")
    kept = list(logger.filters)
    logger.filters = [_PROBES]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield int(server.get_port())
    server.stop()
    logger.filters = kept


def _errors(caplog) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == "websockets.server" and r.levelno >= logging.ERROR]


def test_a_probe_of_the_port_is_not_an_error_but_garbage_is(viser_server, caplog):
    caplog.set_level(logging.DEBUG, logger="websockets.server")
    with socket.create_connection(("127.0.0.1", viser_server), timeout=5):
        pass  # connected, closed without a byte
    wait(lambda: any("without a request" in r.getMessage() for r in caplog.records), 5, "the probe's DEBUG record", poll=0.05)
    assert _errors(caplog) == []
    probe = next(r for r in caplog.records if "without a request" in r.getMessage())
    assert probe.levelno == logging.DEBUG and probe.exc_info is None
    with socket.create_connection(("127.0.0.1", viser_server), timeout=5) as s:
        s.sendall(b"NOT A HANDSHAKE\r\n\r\n")
        s.recv(1024)
    wait(lambda: len(_errors(caplog)) == 1, 5, "the garbage's ERROR record", poll=0.05)
