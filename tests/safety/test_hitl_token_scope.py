"""The HITL token goes only where it was issued (aerodaas/tools/hitl_client.py, docs/security.md "The HITL API").

Without Ray, in-process through the command line's own entry point (``aerodaas.cli.main``): two HTTP servers on
loopback record every ``Authorization`` header they receive; a state file in a private ``AERODAAS_STATE_DIR`` names
server A and token T, as a running ``aerodaas run --hitl`` writes it. ``aerodaas inject --url B`` must not send T
to B (exit 2 naming B and why); ``--url A`` sends it; a plain ``http`` URL off loopback is refused before any
connection is attempted (``socket.create_connection``, what ``http.client`` connects with, records and refuses every
call: no packet ever leaves), token or not, unless ``--insecure-http``, which then warns."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from aerodaas import cli

TOKEN = "state-file-token-" + "T" * 24
OTHER = "another-servers-token-" + "o" * 16
TEST_NET = "192.0.2.1"  # RFC 5737 TEST-NET-1: documentation only; never connected to here


class _Recorder(BaseHTTPRequestHandler):
    """Answers every POST (and GET) like the HITL API's waypoint route and records the Authorization header it
    carried."""

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        self.do_POST()

    def do_POST(self) -> None:  # noqa: N802 - http.server's name
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        self.server.seen.append(self.headers.get("Authorization"))
        body = json.dumps({"added": ["hitl1"], "queue": []}).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args) -> None:
        pass


@pytest.fixture
def servers():
    """Two recording servers on loopback: (url_a, server_a), (url_b, server_b)."""
    out = []
    for _ in range(2):
        srv = ThreadingHTTPServer(("127.0.0.1", 0), _Recorder)
        srv.seen = []
        threading.Thread(target=srv.serve_forever, daemon=True).start()
        out.append((f"http://127.0.0.1:{srv.server_address[1]}", srv))
    yield out
    for _, srv in out:
        srv.shutdown()
        srv.server_close()


@pytest.fixture
def state(tmp_path, monkeypatch, servers):
    """A state file naming server A and TOKEN, written by this (running) process, in a private state folder."""
    d = tmp_path / "state"
    d.mkdir(mode=0o700)
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(d))
    for v in ("AERODAAS_HITL_URL", "AERODAAS_HITL_TOKEN", "AERODAAS_HITL_CAFILE", "http_proxy", "HTTP_PROXY"):
        monkeypatch.delenv(v, raising=False)
    f = d / "hitl.json"
    f.write_text(json.dumps({"url": servers[0][0], "token": TOKEN, "pid": os.getpid(), "drones": ["d1"],
                             "cafile": None}))
    os.chmod(f, 0o600)
    return f


@pytest.fixture
def connections(monkeypatch):
    """Every outgoing TCP connection attempt of the client, recorded; one to an address off loopback is refused
    (OSError) instead of made."""
    attempts: list[tuple[str, int]] = []
    real = socket.create_connection

    def create_connection(address, *args, **kwargs):
        attempts.append((address[0], int(address[1])))
        if address[0] not in ("127.0.0.1", "localhost"):
            raise OSError(f"test: no connection to {address[0]} (never sent)")
        return real(address, *args, **kwargs)

    monkeypatch.setattr(socket, "create_connection", create_connection)
    return attempts


def _inject(capsys, *extra: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = cli.main(["inject", "--drone", "d1", "--waypoint", "3,-4,5", *extra])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_the_state_files_token_goes_to_its_own_server_only(state, servers, connections, capsys):
    (url_a, a), (url_b, b) = servers
    code, out, err = _inject(capsys, "--url", url_b)
    assert code == 2, out + err
    assert f"--url {url_b!r} is not the server that issued the token" in err and "$AERODAAS_HITL_TOKEN" in err, err
    assert b.seen == [] and a.seen == [] and connections == []  # refused before connecting to anything
    assert TOKEN not in out + err

    code, out, err = _inject(capsys, "--url", url_a)
    assert code == 0 and "queued hitl1 for d1" in out, out + err
    assert a.seen == [f"Bearer {TOKEN}"] and b.seen == []

    code, out, err = _inject(capsys)  # no --url: the state file's server, with its token
    assert code == 0 and a.seen == [f"Bearer {TOKEN}"] * 2, out + err

    # another server with its own token: that token, never the state file's
    code, out, err = _inject(capsys, "--url", url_b, "--token", OTHER)
    assert code == 0 and b.seen == [f"Bearer {OTHER}"], out + err


@pytest.mark.parametrize("other", ["scheme", "host name", "port"])
def test_the_same_scheme_host_and_port_are_required(state, servers, connections, capsys, other):
    """Strict origin comparison, no name resolution: ``localhost`` is not ``127.0.0.1``; a path or a trailing slash
    does not change the origin."""
    (url_a, a), _ = servers
    port = url_a.rsplit(":", 1)[1]
    url = {"scheme": f"https://127.0.0.1:{port}", "host name": f"http://localhost:{port}",
           "port": "http://127.0.0.1:80"}[other]
    code, out, err = _inject(capsys, "--url", url)
    assert code == 2 and "is not the server that issued the token" in err, out + err
    assert a.seen == [] and connections == []
    code, out, err = _inject(capsys, "--url", f"HTTP://127.0.0.1:{port}/")
    assert code == 0 and a.seen == [f"Bearer {TOKEN}"], out + err


def test_plain_http_off_loopback_is_refused_before_any_connection(state, servers, connections, capsys):
    url = f"http://{TEST_NET}:8470"
    code, out, err = _inject(capsys, "--url", url)  # the state file's token: not this server's
    assert code == 2 and "is not the server that issued the token" in err, err
    code, out, err = _inject(capsys, "--url", url, "--token", OTHER)  # its own token, but in clear text
    assert code == 2 and f"--url {url!r}: plain http to {TEST_NET!r}" in err and "--insecure-http" in err, err
    assert connections == [] and all(not s.seen for _, s in servers)
    assert OTHER not in out + err and TOKEN not in out + err
    # the explicit choice lifts only the clear-text refusal, with a warning (the connection is refused by the test)
    code, out, err = _inject(capsys, "--url", url, "--token", OTHER, "--insecure-http")
    assert "WARNING: --insecure-http" in err and "cannot reach the HITL API" in err and code == 2, err
    assert connections == [(TEST_NET, 8470)]


@pytest.mark.parametrize("url", ["file:///etc/passwd", "ftp://127.0.0.1/x", "http://user:pw@127.0.0.1:1",
                                 "127.0.0.1:8470"])
def test_a_url_that_is_not_http_s_host_port_is_refused(state, connections, capsys, url):
    code, out, err = _inject(capsys, "--url", url, "--token", OTHER)
    assert code == 2 and repr(url) in err, out + err
    assert connections == []


def test_a_state_file_left_by_a_process_that_is_gone_gives_no_token(state, servers, connections, capsys):
    """A run that did not end cleanly leaves the file; whoever listens on its port now is not the server."""
    p = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                       check=True)
    info = json.loads(state.read_text())
    state.write_text(json.dumps({**info, "pid": int(p.stdout)}))
    code, out, err = _inject(capsys)
    assert code == 2 and "which is not running" in err and servers[0][0] in err, out + err
    assert connections == [] and servers[0][1].seen == []


def test_a_redirect_is_not_followed(state, servers, connections, capsys, monkeypatch):
    """urllib would repeat the Authorization header to wherever a redirect points (a 302 to a POST: as a GET);
    the API never redirects."""
    (url_a, a), (url_b, b) = servers
    answer = _Recorder.do_POST

    def redirect(self):
        if self.server is not a:
            return answer(self)
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        self.server.seen.append(self.headers.get("Authorization"))
        self.send_response(302)
        self.send_header("Location", f"{url_b}/drones/d1/waypoints")
        self.send_header("Content-Length", "0")
        self.end_headers()

    monkeypatch.setattr(_Recorder, "do_POST", redirect)
    code, out, err = _inject(capsys)
    assert code == 1 and "HTTP 302" in err, out + err
    assert a.seen == [f"Bearer {TOKEN}"] and b.seen == []


def test_no_proxy_of_the_environment_sees_a_plain_http_request(state, servers, connections, capsys, monkeypatch):
    """``http_proxy`` would receive the request, token included, in clear text: the client connects directly."""
    (url_a, a), (url_b, b) = servers
    monkeypatch.setenv("http_proxy", url_b)
    for v in ("no_proxy", "NO_PROXY"):
        monkeypatch.delenv(v, raising=False)
    code, out, err = _inject(capsys)
    assert code == 0 and a.seen == [f"Bearer {TOKEN}"] and b.seen == [], out + err
