"""TLS where the HITL API and the live view leave loopback (clusters/tls.py,
aerodaas/liveview/subprotocol.py, aerodaas/liveview/tls_stream.py, aerodaas/tools/hitl.py).

Without Ray: bad certificate and key files, and an address off loopback without them, are refused before Ray with exit
2 naming the field and the value; with a self-signed certificate made here (``cryptography``), the HITL API serves
HTTPS that ``aerodaas inject`` (the project's own client) uses from its owner-only state file, and the live view
serves WSS that a Foxglove-protocol client (aiohttp, tests/liveview/foxglove_ws_client.py) reads only with the token. A plain
client, a client that does not trust the certificate and a client without the token get nothing."""
from __future__ import annotations

import asyncio
import json
import os
import ssl
import stat
import subprocess
import sys
from types import SimpleNamespace

import aiohttp
import pytest

from aerodaas.clusters.tls import ServeAccess, check_exposure, check_tls_files, is_loopback
from aerodaas.liveview.server import LiveServer
from aerodaas.recording.writer import RecordedMessage
from aerodaas.tools.hitl import HitlServer

from tests.inputs.cli_inprocess import run_cli
from tests.liveview.foxglove_ws_client import collect
from tests.inputs.test_app_errors_before_ray import APP, _refused_before_ray
from tests.inputs.test_app_value import fresh_ray_tmp
from tests.safety.tls_certs import encrypted_key, self_signed

TOKEN = "live-token-" + "x" * 20


@pytest.fixture
def certs(tmp_path):
    crt, key = self_signed(tmp_path)
    return SimpleNamespace(crt=crt, key=key, dir=tmp_path)


def _client_context(crt) -> ssl.SSLContext:
    return ssl.create_default_context(cafile=str(crt))


# ---------------------------------------------------------------------------------------------- the files, the rule
@pytest.mark.parametrize("case,field,expect", [
    ("missing_cert", "hitl.tls_cert", "No such file"),
    ("cert_is_a_folder", "hitl.tls_cert", "is not a regular file"),
    ("cert_not_pem", "hitl.tls_cert", "is not a PEM certificate"),
    ("key_world_readable", "hitl.tls_key", "readable or writable by other users (mode 0644)"),
    ("key_group_readable", "hitl.tls_key", "(mode 0640)"),
    ("key_encrypted", "hitl.tls_key", "is encrypted"),
    ("key_of_another_cert", "hitl.tls_key", "is not a PEM private key of the certificate"),
    ("key_not_pem", "hitl.tls_key", "is not a PEM private key"),
])
def test_bad_certificate_and_key_files_are_refused_naming_the_field_and_file(certs, case, field, expect):
    crt, key = str(certs.crt), str(certs.key)
    if case == "missing_cert":
        crt = str(certs.dir / "nowhere.crt")
    elif case == "cert_is_a_folder":
        crt = str(certs.dir)
    elif case == "cert_not_pem":
        (certs.dir / "x.crt").write_text("not a certificate\n")
        crt = str(certs.dir / "x.crt")
    elif case == "key_world_readable":
        os.chmod(key, 0o644)
    elif case == "key_group_readable":
        os.chmod(key, 0o640)
    elif case == "key_encrypted":
        key = str(encrypted_key(certs.key, certs.dir / "enc.key"))
    elif case == "key_of_another_cert":
        key = str(self_signed(certs.dir, "other")[1])
    elif case == "key_not_pem":
        (certs.dir / "junk.key").write_bytes(os.urandom(64))
        os.chmod(certs.dir / "junk.key", 0o600)
        key = str(certs.dir / "junk.key")
    with pytest.raises(ValueError) as e:
        check_tls_files(crt, key, "hitl.tls_cert", "hitl.tls_key")
    msg = str(e.value)
    assert msg.startswith(field) and expect in msg, msg
    assert (crt if field.endswith("cert") else key) in msg, msg


def test_off_loopback_needs_a_certificate_or_insecure(certs):
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost") and is_loopback("127.8.0.1")
    assert not is_loopback("0.0.0.0") and not is_loopback("10.0.0.1") and not is_loopback("drone-gw.example")
    for host in ("0.0.0.0", "192.0.2.7", "::"):
        with pytest.raises(ValueError, match=r"--live: .* is not a loopback address .* --tls-cert and --tls-key"):
            check_exposure(host, None, None, False, "--live", "--tls-cert", "--tls-key", "--insecure")
        check_exposure(host, None, None, True, "--live", "--tls-cert", "--tls-key", "--insecure")
        check_exposure(host, str(certs.crt), str(certs.key), False, "--live", "--tls-cert", "--tls-key", "--insecure")
    check_exposure("127.0.0.1", None, None, False, "--live", "--tls-cert", "--tls-key", "--insecure")
    with pytest.raises(ValueError, match="--tls-cert is given without --tls-key"):
        check_exposure("127.0.0.1", str(certs.crt), None, False, "--live", "--tls-cert", "--tls-key", "--insecure")


def _app(tmp_path, hitl: dict | None = None):
    env = {"robots": [{"id": "d1"}], "compute": [{"id": "edge", "tier": "edge"}]}
    if hitl is not None:
        env["hitl"] = hitl
    (tmp_path / "env.json").write_text(json.dumps(env))
    app = tmp_path / "app.py"
    app.write_text(APP.format(body=""))
    return app


def _run_cli(tmp_path, *args: str, in_process: bool = False):
    """``aerodaas ARGS`` (in ``tmp_path``, a new empty RAY_TMPDIR) in a subprocess, or with ``in_process`` (bad
    input) in this process (:func:`tests.inputs.cli_inprocess.run_cli`, which fails the test if Ray is started)."""
    ray_tmp = fresh_ray_tmp(tmp_path)
    if in_process:
        return run_cli(*args, cwd=tmp_path, env={**os.environ, "RAY_TMPDIR": str(ray_tmp)}), ray_tmp
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True, cwd=tmp_path,
                       env={**os.environ, "RAY_TMPDIR": str(ray_tmp)}, timeout=300)
    return p, ray_tmp


@pytest.mark.parametrize("case", ["live_no_cert", "live_world_readable_key", "hitl_no_cert", "hitl_missing_cert",
                                  "hitl_bad_key"])
def test_aerodaas_run_refuses_clear_text_off_loopback_and_bad_files_before_ray(tmp_path, certs, case):
    if case == "live_no_cert":
        args = ("run", str(_app(tmp_path)), "--live", "0.0.0.0:0")
        said = ("--live: '0.0.0.0' is not a loopback address", "--tls-cert", "--insecure")
    elif case == "live_world_readable_key":
        os.chmod(certs.key, 0o604)
        args = ("run", str(_app(tmp_path)), "--live", "0.0.0.0:0", "--tls-cert", str(certs.crt), "--tls-key",
                str(certs.key))
        said = (f"--tls-key: '{certs.key}' is readable or writable by other users (mode 0604)",)
    elif case == "hitl_no_cert":
        args = ("run", str(_app(tmp_path, {"enabled": True, "host": "0.0.0.0", "port": 0})))
        said = ("hitl.host: '0.0.0.0' is not a loopback address", "hitl.tls_cert", "hitl.insecure")
    elif case == "hitl_missing_cert":
        args = ("run", str(_app(tmp_path, {"enabled": True, "host": "0.0.0.0", "port": 0,
                                           "tls_cert": "gone.crt", "tls_key": "gone.key"})))
        said = ("hitl.tls_cert: file 'gone.crt' not found",)
    else:
        (certs.dir / "bad.key").write_text("-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n")
        os.chmod(certs.dir / "bad.key", 0o600)
        args = ("run", str(_app(tmp_path, {"enabled": True, "host": "0.0.0.0", "port": 0,
                                           "tls_cert": certs.crt.name, "tls_key": "bad.key"})))
        said = (f"hitl.tls_key: '{certs.dir / 'bad.key'}' is not a PEM private key",)
    # the first case as the real command (exit 2 and no Ray session, from the process itself), the others in-process
    p, ray_tmp = _run_cli(tmp_path, *args, "--quiet", in_process=case != "live_no_cert")
    _refused_before_ray(p, ray_tmp, *said)


def test_aerodaas_replay_refuses_clear_text_off_loopback(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"")
    p = run_cli("replay", str(tmp_path / "x.mcap"), "--live", "0.0.0.0:0")
    assert p.returncode == 2 and "--live: '0.0.0.0' is not a loopback address" in p.stderr, p.stderr


# ---------------------------------------------------------------------------------------------- the HITL API
class _Call:
    def __init__(self, value):
        self.value = value


class _Fake:
    """A drone or scheduler handle answering in-process (``h.method.remote(...)``, read with ``_get``)."""

    def __init__(self):
        self.added = []

    def __getattr__(self, name):
        def remote(*args):
            if name == "add_navigation":
                self.added.append(args[0])
                return _Call({"queue": []})
            if name == "snapshot":
                return _Call([])
            return _Call({"state": "NAVIGATING", "position": [0.0, 0.0, 2.0], "visited": 0})
        return SimpleNamespace(remote=remote)


def _get(call, timeout=None):
    return call.value


@pytest.fixture
def https_api(certs, tmp_path, monkeypatch):
    state = tmp_path / "state"
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(state))
    for v in ("AERODAAS_HITL_URL", "AERODAAS_HITL_TOKEN", "AERODAAS_HITL_CAFILE"):
        monkeypatch.delenv(v, raising=False)
    sched = _Fake()
    srv = HitlServer({"d1": {"drone": _Fake(), "scheduler": sched}}, host="0.0.0.0", port=0, get=_get,
                     cert_file=str(certs.crt), key_file=str(certs.key)).start()
    yield SimpleNamespace(srv=srv, sched=sched, state=state, port=srv.port)
    srv.stop()


def _inject(*extra: str, env: dict | None = None):
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "inject", "--drone", "d1", "--waypoint", "3,-4,5",
                           *extra], capture_output=True, text=True, timeout=120, env={**os.environ, **(env or {})})


def test_hitl_api_serves_https_and_aerodaas_inject_uses_it_from_the_owner_only_state_file(https_api, certs):
    f = https_api.state / "hitl.json"
    assert stat.S_IMODE(f.stat().st_mode) == 0o600
    info = json.loads(f.read_text())
    assert info["url"].startswith("https://") and info["cafile"] == str(certs.crt)
    p = _inject()
    assert p.returncode == 0 and "queued hitl1 for d1" in p.stdout, p.stdout + p.stderr
    assert [w.id for w in https_api.sched.added[0].waypoints] == ["hitl1"]
    # the URL and token given, the certificate not trusted (the system's CAs): refused by the client, nothing added
    url = f"https://127.0.0.1:{https_api.port}"
    p = _inject("--url", url, "--token", https_api.srv.token)
    assert p.returncode == 2 and "CERTIFICATE_VERIFY_FAILED" in p.stderr, p.stderr
    p = _inject("--url", url, "--token", "wrong-token-0123456789", "--cacert", str(certs.crt))
    assert p.returncode == 1 and "HTTP 401" in p.stderr, p.stderr
    assert len(https_api.sched.added) == 1
    # plain HTTP to the TLS port gets no answer of the API
    p = _inject("--url", f"http://127.0.0.1:{https_api.port}", "--token", https_api.srv.token)
    assert p.returncode != 0 and len(https_api.sched.added) == 1, p.stdout + p.stderr


def test_a_stale_world_readable_state_file_is_replaced_owner_only(certs, tmp_path, monkeypatch):
    """The state file is written 0600 even over an older file that was 0644 (O_CREAT keeps an existing mode)."""
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path / "st"))
    (tmp_path / "st").mkdir()
    old = tmp_path / "st" / "hitl.json"
    old.write_text("{}")
    os.chmod(old, 0o644)
    srv = HitlServer({}, port=0, get=_get).start()
    try:
        assert stat.S_IMODE(old.stat().st_mode) == 0o600
        assert json.loads(old.read_text())["token"] == srv.token
    finally:
        srv.stop()


# ---------------------------------------------------------------------------------------------- the live view
def _publish(srv: LiveServer, n: int) -> None:
    for i in range(n):
        srv.publish(RecordedMessage("/d1/state", "aerodaas.State", "jsonschema", b"{}", "json", 100 + i,
                                    json.dumps({"i": i}).encode()))


@pytest.fixture
def wss(certs):
    srv = LiveServer("0.0.0.0:0", catchup_s=3600, access=ServeAccess(str(certs.crt), str(certs.key), TOKEN))
    _publish(srv, 5)
    yield srv
    srv.stop(linger_s=0)


def _handshake_status(url: str, ssl_ctx, headers: dict | None = None) -> int | str:
    async def go():
        async with aiohttp.ClientSession() as s:
            try:
                async with s.ws_connect(url, protocols=("foxglove.sdk.v1",), ssl=ssl_ctx, headers=headers):
                    return 101
            except aiohttp.WSServerHandshakeError as e:
                return e.status
            except aiohttp.ClientError as e:
                return type(e).__name__
    return asyncio.run(go())


def test_live_view_serves_wss_to_a_client_with_the_token(wss, certs):
    assert wss.url == f"wss://0.0.0.0:{wss.port}"
    ctx = _client_context(certs.crt)
    got = collect(f"wss://127.0.0.1:{wss.port}/?token={TOKEN}", {"/d1/state": 5}, timeout_s=60, ssl=ctx)
    assert [json.loads(m)["i"] for _, m in got["messages"]["/d1/state"]] == [0, 1, 2, 3, 4]
    got = collect(f"wss://127.0.0.1:{wss.port}", {"/d1/state": 5}, timeout_s=60, ssl=ctx,
                  headers={"Authorization": f"Bearer {TOKEN}"})
    assert len(got["messages"]["/d1/state"]) == 5


def test_live_view_refuses_clients_without_the_token_or_tls(wss, certs):
    ctx = _client_context(certs.crt)
    base = f"wss://127.0.0.1:{wss.port}"
    assert _handshake_status(base, ctx) == 401
    assert _handshake_status(f"{base}/?token=wrong-{TOKEN}", ctx) == 401
    assert _handshake_status(base, ctx, {"Authorization": "Bearer nope-nope-nope-nope"}) == 401
    # a client that does not trust the certificate, and a plain-text client, do not get a WebSocket at all
    untrusted = _handshake_status(f"{base}/?token={TOKEN}", ssl.create_default_context())
    assert untrusted == "ClientConnectorCertificateError", untrusted
    assert _handshake_status(f"ws://127.0.0.1:{wss.port}/?token={TOKEN}", False) != 101
    assert wss.subscriptions == 0


@pytest.mark.e2e
def test_insecure_serves_clear_text_off_loopback_and_the_summary_says_so(tmp_path, ray_session):
    """``--insecure`` and ``hitl.insecure``: the run serves plain WS and HTTP on every address (the live view still
    asks its token off loopback), warns at start, and its summary repeats the choice for each server. In-process on
    the pytest worker's shared Ray session (the servers run in the driver; the session is checked clean after)."""
    app = _app(tmp_path, {"enabled": True, "host": "0.0.0.0", "port": 0, "insecure": True})
    p = run_cli("run", str(app), "--live", "0.0.0.0:0", "--insecure", "--quiet", cwd=tmp_path, shared_ray=True)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert "human-in-the-loop API at http://0.0.0.0:" in p.stdout and "live view at ws://0.0.0.0:" in p.stdout
    summary = p.stdout[p.stdout.index("mission outcome:"):]
    assert "INSECURE: the HITL API at http://0.0.0.0:" in summary, summary
    assert "INSECURE: the live view at ws://0.0.0.0:" in summary, summary
    assert "WARNING: the live view serves plain WebSocket off loopback" in p.stderr, p.stderr[-2000:]
