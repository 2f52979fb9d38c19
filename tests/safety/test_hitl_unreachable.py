"""The HITL API in front of a drone actor that does not answer: SIGSTOPped (stopped, or restarting) and killed.
Every request is answered 503 with Retry-After (never 500, never a 10 s wait), and the API answers again once the
actor does. Real Ray actors (the ``ray_session`` fixture), the real FastAPI app under uvicorn."""
from __future__ import annotations

import http.client
import json
import os
import signal
import time

import pytest
import ray

from aerodaas.tools.hitl import CALL_TIMEOUT_S, HitlServer

pytestmark = pytest.mark.faults

TOKEN = "u" * 24


@ray.remote(num_cpus=0)
class FakeComponents:
    """Answers like a drone and a scheduler component (``call(cid, method)``)."""

    def pid(self) -> int:
        return os.getpid()

    def call(self, cid: str, method, *args):
        method = method.__name__  # the driver's typed handles pass the component class's method itself
        if method == "status":
            return {"state": "NAVIGATING", "position": [0.0, 0.0, 2.0], "visited": 0}
        if method == "snapshot":
            return []
        return True


def _send(port: int, method: str, path: str, body: bytes | None = None) -> tuple[int, dict, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    c.request(method, path, body=body, headers={"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"})
    r = c.getresponse()
    raw = r.read()
    c.close()
    return r.status, json.loads(raw or b"null"), dict(r.getheaders())


def _answers_200(port: int, path: str, tries: int = 120) -> bool:
    """Whether GET ``path`` comes back 200 within ``tries`` requests (0.5 s apart), every other answer being a 503
    with ``Retry-After: 1`` (AssertionError otherwise). On a loaded machine an actor's first answer, or its first
    after SIGCONT, can come later than the API's :data:`CALL_TIMEOUT_S` (CI saw it once; the cause was not
    reproduced here); that 503 is correct, so the test asks again instead of racing the clock."""
    for _ in range(tries):
        status, body, headers = _send(port, "GET", path)
        if status == 200:
            return True
        assert status == 503 and headers.get("retry-after") == "1", (status, body)
        time.sleep(0.5)
    return False


def test_stopped_or_dead_drone_actor_is_503_never_500(ray_session, tmp_path, monkeypatch):
    from aerodaas.actors.handles import DroneHandle, SchedulerHandle

    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path))
    actor = FakeComponents.remote()
    pid = ray.get(actor.pid.remote(), timeout=120)
    srv = HitlServer({"d1": {"drone": DroneHandle(actor, "d1/drone"),
                             "scheduler": SchedulerHandle(actor, "d1/scheduler")}}, port=0, token=TOKEN).start()
    try:
        assert _answers_200(srv.port, "/drones/d1")
        os.kill(pid, signal.SIGSTOP)  # the actor's process stops answering (as a hung or restarting one)
        try:
            for method, path, body in (("GET", "/drones/d1", None), ("GET", "/drones", None),
                                       ("POST", "/drones/d1/waypoints", b'{"waypoints": [{"x": 1, "y": 1, "z": 2}]}'),
                                       ("POST", "/drones/d1/clear", b'{"scope": "injected"}'),
                                       ("POST", "/drones/d1/pause", None)):
                status, body_out, headers = _send(srv.port, method, path, body)
                assert status == 503, (method, path, status, body_out)
                assert headers.get("retry-after") == "1" and "does not answer" in body_out["detail"]
        finally:
            os.kill(pid, signal.SIGCONT)
        assert _answers_200(srv.port, "/drones/d1")  # back
        ray.kill(actor, no_restart=True)  # gone for good
        for _ in range(240):  # ray.kill is asynchronous: wait until the actor is seen dead
            try:
                ray.get(actor.pid.remote(), timeout=30)
            except ray.exceptions.RayActorError:
                break
            time.sleep(0.5)
        else:
            pytest.fail("the killed actor still answers")
        status, body_out, _ = _send(srv.port, "GET", "/drones/d1")
        assert status == 503, body_out
    finally:
        srv.stop()
    assert CALL_TIMEOUT_S <= 2.0  # the bound a request waits for an actor (the whole answer within 2 s)
