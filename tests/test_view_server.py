"""fourbar-view as a server seen from the network: where it binds, whom it answers (issue 36).

A real `fourbar-view` process on a real run folder, asked with plain HTTP (http.client):
the page and Bokeh's websocket handshake (an HTTP Upgrade request) under good and bad
``Host`` and ``Origin`` headers, with ``BOKEH_ALLOW_WS_ORIGIN`` set in its environment.
No timing is asserted: the waits are hang guards only.
"""
from __future__ import annotations

import http.client
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from support import FOURBAR_RUN, case_file
from view.served import AddressError, Bind, host_allowed, parse_address

FOURBAR_VIEW = str(Path(sys.executable).parent / "fourbar-view")
HANG_GUARD_S = 60          # a page build on a loaded 2-core machine; not a performance bound
WS_HANDSHAKE = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
                "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}


@pytest.fixture(scope="module")
def run_folder(native_fmu, tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("viewserver")
    out = tmp / "run"
    done = subprocess.run([FOURBAR_RUN, str(case_file("case1_normal", native_fmu, tmp)), "--stop", "5", "--out",
                           str(out), "--quiet"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return out


class Server:
    """A running `fourbar-view FOLDER --quiet ...` (its first line: the URL)."""

    def __init__(self, folder: Path, *args: str, env: dict[str, str] | None = None):
        self.proc = subprocess.Popen([FOURBAR_VIEW, str(folder), "--quiet", *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env={**os.environ, **(env or {})})
        self.url = self.proc.stdout.readline().strip()
        assert self.url.startswith("http://"), (self.url, self.proc.stderr.read() if self.proc.poll() else "")
        hostport = self.url.removeprefix("http://").rstrip("/")
        self.port = int(hostport.rsplit(":", 1)[1])

    def get(self, path: str = "/", *, host: str | None = None, connect: str = "127.0.0.1",
            headers: dict[str, str] | None = None) -> tuple[int, bytes]:
        c = http.client.HTTPConnection(connect, self.port, timeout=HANG_GUARD_S)
        try:
            c.putrequest("GET", path, skip_host=True)
            c.putheader("Host", host if host is not None else f"127.0.0.1:{self.port}")
            for k, v in (headers or {}).items():
                c.putheader(k, v)
            c.endheaders()
            r = c.getresponse()
            return r.status, r.read()
        finally:
            c.close()

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGTERM)
        try:
            _, err = self.proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return err


def _listening_address(pid: int, port: int) -> str:
    """The local address the process listens on at ``port`` (from /proc/net/tcp{,6})."""
    import psutil

    found = {c.laddr.ip for c in psutil.Process(pid).net_connections(kind="inet")
             if c.status == psutil.CONN_LISTEN and c.laddr.port == port}
    assert len(found) == 1, found
    return found.pop()


def test_by_default_it_binds_loopback_and_says_so(run_folder):
    server = Server(run_folder)
    try:
        assert server.url == f"http://127.0.0.1:{server.port}/"
        assert _listening_address(server.proc.pid, server.port) == "127.0.0.1"
        status, body = server.get()
        assert status == 200 and b"bokeh" in body.lower()
        assert server.get(host=f"localhost:{server.port}")[0] == 200
    finally:
        err = server.stop()
    assert "warning" not in err, err


def test_other_host_headers_get_403(run_folder):
    """DNS rebinding: a page from evil.example whose name now points at 127.0.0.1 sends
    ``Host: evil.example``; it gets 403 and no session (the page, Bokeh's static files and
    the websocket alike)."""
    server = Server(run_folder)
    try:
        for host in (f"evil.example:{server.port}", "evil.example", f"127.0.0.1:{server.port + 1}",
                     f"127.0.0.2:{server.port}", ""):
            status, body = server.get(host=host)
            assert status == 403, (host, status)
            assert b"not served here" in body
        status, _ = server.get("/static/js/bokeh.min.js", host="evil.example")
        assert status == 403
        status, _ = server.get("/ws", host=f"evil.example:{server.port}",
                               headers={**WS_HANDSHAKE, "Origin": f"http://evil.example:{server.port}"})
        assert status == 403
    finally:
        server.stop()


def test_bokeh_allow_ws_origin_does_not_admit_an_origin(run_folder):
    """BOKEH_ALLOW_WS_ORIGIN=evil.example in the environment: the websocket still refuses
    Origin evil.example (Bokeh would replace its origin list by the variable's) and accepts
    the page's own origin; the server says it ignored the variable."""
    server = Server(run_folder, env={"BOKEH_ALLOW_WS_ORIGIN": "evil.example,evil.example:80"})
    try:
        status, _ = server.get("/ws", headers={**WS_HANDSHAKE, "Origin": "http://evil.example"})
        assert status == 403
        status, _ = server.get("/ws", headers={**WS_HANDSHAKE, "Origin": f"http://127.0.0.1:{server.port}"})
        assert status == 101          # the handshake itself; Bokeh closes it for want of a session token
    finally:
        err = server.stop()
    assert "ignoring BOKEH_ALLOW_WS_ORIGIN" not in err     # --quiet says nothing ...
    loud = subprocess.Popen([FOURBAR_VIEW, str(run_folder)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "BOKEH_ALLOW_WS_ORIGIN": "evil.example"})
    loud.stdout.readline()
    loud.send_signal(signal.SIGTERM)
    _, err = loud.communicate(timeout=30)
    assert "ignoring BOKEH_ALLOW_WS_ORIGIN" in err, err      # ... otherwise it says what it ignored


def test_allow_host_admits_a_named_host_by_flag(run_folder):
    server = Server(run_folder, "--allow-host", "viewer.example")
    try:
        assert server.get(host=f"viewer.example:{server.port}")[0] == 200
        status, _ = server.get("/ws", headers={**WS_HANDSHAKE, "Origin": f"http://viewer.example:{server.port}"})
        assert status == 101
        assert server.get(host=f"evil.example:{server.port}")[0] == 403
    finally:
        server.stop()


def test_another_address_is_bound_as_asked_with_a_warning(run_folder):
    """--address 0.0.0.0: listens on every interface, says so and warns that the page has no
    authentication; the link printed names this computer; Host checks still apply."""
    server = Server(run_folder, "--address", "0.0.0.0")
    try:
        assert _listening_address(server.proc.pid, server.port) == "0.0.0.0"
        assert server.url == f"http://{socket.gethostname()}:{server.port}/"
        assert server.get(host=f"127.0.0.1:{server.port}")[0] == 200
        assert server.get(host=f"evil.example:{server.port}")[0] == 403
    finally:
        err = server.stop()
    assert "warning" in err and "no authentication" in err and f"0.0.0.0:{server.port}" in err, err


def test_bad_addresses_exit_2_with_a_message(run_folder):
    # 192.0.2.1: TEST-NET-1 (RFC 5737), an address no computer has
    for address, said in (("no.such.host.invalid", "not an address"), ("http://x", "not a URL"),
                          ("192.0.2.1", "cannot listen there")):
        done = subprocess.run([FOURBAR_VIEW, str(run_folder), "--address", address], capture_output=True, text=True,
                              timeout=HANG_GUARD_S)
        assert done.returncode == 2 and "--address" in done.stderr and said in done.stderr, done.stderr
        assert "Traceback" not in done.stderr


def test_address_parsing_and_host_names():
    """The one parser of --address / --dashboard: host, port, IPv6 in brackets; bad input
    named."""
    assert parse_address(":8787", 0, option="--dashboard") == Bind("127.0.0.1", 8787)
    assert parse_address("8787", 0, option="--dashboard") == Bind("127.0.0.1", 8787)
    assert parse_address("0.0.0.0:9000", 8787, option="--dashboard") == Bind("0.0.0.0", 9000)
    assert parse_address("[::1]:9000", 8787, option="--dashboard") == Bind("::1", 9000)
    assert parse_address("localhost", 8787, option="--dashboard") == Bind("localhost", 8787)
    for bad in ("1.2.3.4:99999", "::1", "[::1", "host:port"):
        with pytest.raises(AddressError, match="--dashboard"):
            parse_address(bad, 8787, option="--dashboard")
    loop = Bind("127.0.0.1", 5006)
    assert loop.loopback and loop.warning("x") is None
    assert set(loop.host_names()) == {"127.0.0.1:5006", "localhost:5006", "[::1]:5006"}
    assert host_allowed("LOCALHOST:5006", loop.host_names()) and not host_allowed("localhost", loop.host_names())
    assert not host_allowed(None, loop.host_names())
    lan = Bind("0.0.0.0", 5006)
    assert not lan.loopback and "no authentication" in lan.warning("x")
    assert "127.0.0.1:5006" in lan.host_names() and f"{socket.gethostname().lower()}:5006" in lan.host_names()
