"""One exposure rule for every server AeroDaaS starts, from its Python API as from the command line
(:func:`aerodaas.clusters.tls.check_exposure`, docs/security.md "Threat model: the doors").

Without Ray: the live view (``LiveServer``, and ``replay``, which builds one) and the HITL API (``HitlServer``)
bound off loopback without TLS, or without a token, raise ``ValueError`` naming the parameter, before anything
listens (foxglove-sdk's ``start_server`` is never called; uvicorn never starts); with the explicit insecure choice
they start and say so (``insecure``, which the run summary repeats); on loopback they start as before, nothing
asked."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from aerodaas.clusters.tls import MIN_TOKEN_CHARS, ServeAccess, check_exposure
from aerodaas.liveview.server import LiveServer, replay
from aerodaas.tools.hitl import HitlServer

from tests.safety.tls_certs import self_signed

TOKEN = "exposure-token-" + "z" * 20
OFF_LOOPBACK = "0.0.0.0"  # every address of this machine: the case the rule is about (nothing is sent anywhere)


@pytest.fixture
def starts(monkeypatch):
    """Every foxglove-sdk server start of the live view, recorded (the real one still runs)."""
    import foxglove

    calls = []

    start = foxglove.start_server

    def recorded(*args, **kwargs):
        calls.append(kwargs.get("host"))
        return start(*args, **kwargs)

    monkeypatch.setattr(foxglove, "start_server", recorded)
    return calls


@pytest.mark.parametrize("access, says", [
    (None, "no TLS certificate is given: give ServeAccess.cert_file and ServeAccess.key_file"),
    (ServeAccess(token=TOKEN), "no TLS certificate is given"),
    (ServeAccess(insecure=True), "its clients would present no token: give ServeAccess.token"),
    (ServeAccess(token="x" * (MIN_TOKEN_CHARS - 1), insecure=True), "a token shorter than 16 characters"),
    (ServeAccess(token="", insecure=True), "no token"),
])
def test_the_live_views_python_api_refuses_an_unprotected_address_off_loopback(starts, access, says):
    with pytest.raises(ValueError) as e:
        LiveServer(f"{OFF_LOOPBACK}:0", access=access)
    msg = str(e.value)
    assert msg.startswith(f"LiveServer('{OFF_LOOPBACK}:0'): '{OFF_LOOPBACK}' is not a loopback address") and says in msg
    assert "bind 127.0.0.1" in msg and (TOKEN not in msg)
    assert starts == []  # refused before any server started


def test_the_live_view_off_loopback_starts_with_tls_and_a_token_or_insecure_and_says_which(starts, tmp_path):
    crt, key = self_signed(tmp_path)
    srv = LiveServer(f"{OFF_LOOPBACK}:0", access=ServeAccess(str(crt), str(key), TOKEN))
    try:
        assert srv.url.startswith("wss://") and srv.insecure is False
    finally:
        srv.stop(linger_s=0)
    srv = LiveServer(f"{OFF_LOOPBACK}:0", access=ServeAccess(token=TOKEN, insecure=True))
    try:
        assert srv.url.startswith(f"ws://{OFF_LOOPBACK}:") and srv.insecure is True
    finally:
        srv.stop(linger_s=0)
    assert len(starts) == 2


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost"])
def test_the_live_view_on_loopback_starts_as_before(starts, host):
    srv = LiveServer(f"{host}:0")
    try:
        assert srv.url.startswith(f"ws://{host}:") and srv.insecure is False and srv.access.token is None
    finally:
        srv.stop(linger_s=0)
    # an insecure choice on loopback changes nothing: nothing is served in clear text off this machine
    srv = LiveServer(f"{host}:0", access=ServeAccess(insecure=True))
    try:
        assert srv.insecure is False
    finally:
        srv.stop(linger_s=0)


def _mcap(path) -> str:
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("aerodaas.State", "jsonschema", b"{}")
        cid = w.register_channel("/d1/state", "json", sid)
        w.add_message(cid, log_time=1, publish_time=1, data=json.dumps({"i": 0}).encode())
        w.finish()
    return str(path)


def test_replays_python_api_applies_the_same_rule(starts, tmp_path):
    f = _mcap(tmp_path / "x.mcap")
    with pytest.raises(ValueError, match=r"LiveServer\('0\.0\.0\.0:0'\): '0\.0\.0\.0' is not a loopback address"):
        replay(f, f"{OFF_LOOPBACK}:0", speed=1000.0)
    assert starts == []
    out = replay(f, "127.0.0.1:0", speed=1000.0, settle_s=0)
    assert out["messages"] == 1 and len(starts) == 1


# ---------------------------------------------------------------------------------------------- the HITL API
@pytest.fixture
def state(tmp_path, monkeypatch):
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path / "state"))
    return tmp_path / "state"


def _get(call, timeout=None):
    return call


def test_the_hitl_apis_python_api_refuses_clear_text_off_loopback(state, monkeypatch):
    import uvicorn

    monkeypatch.setattr(uvicorn, "Server", lambda *a, **k: pytest.fail("uvicorn started"))
    with pytest.raises(ValueError) as e:
        HitlServer({}, host=OFF_LOOPBACK, port=0, get=_get)
    msg = str(e.value)
    assert msg.startswith(f"HitlServer(host='{OFF_LOOPBACK}'): '{OFF_LOOPBACK}' is not a loopback address"), msg
    assert "give cert_file and key_file" in msg and "insecure=True" in msg, msg
    assert not (state / "hitl.json").exists()


def test_the_hitl_api_off_loopback_starts_with_tls_or_insecure_and_the_summary_reads_which(state, tmp_path):
    crt, key = self_signed(tmp_path)
    srv = HitlServer({}, host=OFF_LOOPBACK, port=0, get=_get, cert_file=str(crt), key_file=str(key)).start()
    try:
        assert srv.url.startswith("https://") and srv.insecure is False
    finally:
        srv.stop()
    # through the driver's own step, which puts what the server says into the run summary's INSECURE lines
    from aerodaas.runtime import driver

    hitl_cfg = SimpleNamespace(enabled=True, host=OFF_LOOPBACK, port=0, token=None, docs=False, tls_cert=None,
                               tls_key=None, insecure=True)
    run = SimpleNamespace(env=SimpleNamespace(cfg=SimpleNamespace(hitl=hitl_cfg), hitl=None), handles={},
                          insecure=[], opts=SimpleNamespace(hitl=True, hitl_port=None, tls_cert=None, tls_key=None,
                                                            insecure=False))
    srv = driver._start_hitl(run)
    try:
        assert srv.insecure is True and srv.url.startswith(f"http://{OFF_LOOPBACK}:")
        assert run.insecure == [f"the HITL API at {srv.url}"]
    finally:
        srv.stop()


def test_the_hitl_api_on_loopback_starts_as_before(state):
    srv = HitlServer({}, port=0, get=_get).start()
    try:
        assert srv.url.startswith("http://127.0.0.1:") and srv.insecure is False
        assert json.loads((state / "hitl.json").read_text())["url"] == srv.url
    finally:
        srv.stop()


def test_the_rule_itself_asks_a_token_off_loopback_even_over_tls(tmp_path):
    """What a new server (an ML backend, a helper) calls: :func:`check_exposure` with the token it will ask."""
    crt, key = self_signed(tmp_path)
    for token in (None, "", "short"):
        with pytest.raises(ValueError, match="--label-serve: '10.0.0.7' is not a loopback address and its clients"):
            check_exposure("10.0.0.7", str(crt), str(key), False, "--label-serve", token=token)
    check_exposure("10.0.0.7", str(crt), str(key), False, "--label-serve", token=TOKEN)
    check_exposure("10.0.0.7", str(crt), str(key), False, "--label-serve")  # True: the server generates one
    check_exposure("127.0.0.1", None, None, False, "--label-serve", token=None)
