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

from aerodaas.tools.hitl import HitlServer

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
        if method in ("add_navigation", "clear_navigation"):
            return {}  # the real scheduler component's: a dict merged into the answer
        return True


def _send(port: int, method: str, path: str, body: bytes | None = None) -> tuple[int, dict, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    c.request(method, path, body=body, headers={"Authorization": f"Bearer {TOKEN}", "Content-Type": "application/json"})
    r = c.getresponse()
    raw = r.read()
    c.close()
    return r.status, json.loads(raw or b"null"), dict(r.getheaders())


#: a body each POST route takes (it must get past validation to reach the actor)
BODIES = {"/drones/{robot_id}/waypoints": b'{"waypoints": [{"x": 1, "y": 1, "z": 2}]}',
          "/drones/{robot_id}/clear": b'{"scope": "injected"}'}


def _routes(srv) -> list[tuple[str, str, bytes | None]]:
    """(method, path for drone d1, body) of every route in the app's own route table (``app.routes``), HEAD and
    OPTIONS aside: each one calls the drone's actor."""
    out = []
    for r in srv.app.routes:
        for m in sorted(getattr(r, "methods", None) or ()):
            if m not in ("HEAD", "OPTIONS"):
                out.append((m, r.path.replace("{robot_id}", "d1"), BODIES.get(r.path, b"{}") if m == "POST" else None))
    return out


def _process_state(pid: int) -> str:
    """The actor process's state letter from /proc/<pid>/stat (``T``: stopped by a signal; proc(5))."""
    stat = open(f"/proc/{pid}/stat").read()
    return stat[stat.rindex(")") + 2]


def _actor_answers(actor) -> bool:
    """Whether the actor answers a call of its own (not through the API)."""
    try:
        ray.get(actor.pid.remote(), timeout=30)
        return True
    except ray.exceptions.GetTimeoutError:
        return False


def _all_503(srv, why: str, still=lambda: True) -> None:
    """Every route (:func:`_routes`) answers 503 with ``Retry-After: 1`` and a detail that says the actor does not
    answer; ``still()`` (the observed state that makes 503 right) holds after each answer."""
    for method, path, body in _routes(srv):
        status, body_out, headers = _send(srv.port, method, path, body)
        assert still(), f"{why}: the state changed during {method} {path}"
        assert status == 503, (why, method, path, status, body_out)
        assert headers.get("retry-after") == "1" and "does not answer" in body_out["detail"], (why, headers, body_out)


def test_stopped_or_dead_drone_actor_is_503_never_500(ray_session, tmp_path, monkeypatch):
    """Driven by the actor's observed state: it answers -> every route 200 (eventually: see below); its process
    stopped (SIGSTOP, seen as state ``T`` in /proc, before and after each request) -> every route 503 with
    Retry-After, answered while the actor is still stopped (no request waits for the actor to come back); continued
    and answering its own calls again -> 200; killed and seen dead -> every route 503 with Retry-After.

    After SIGCONT, or on the first call, a loaded machine may answer a call later than the API's bound, so a 503 is
    right then too: the test asks again (each answer either 200 or a 503 with Retry-After) instead of racing it."""
    from aerodaas.actors.builtin.handles import DroneHandle, SchedulerHandle

    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path))
    actor = FakeComponents.remote()
    pid = ray.get(actor.pid.remote(), timeout=120)
    srv = HitlServer({"d1": {"drone": DroneHandle(actor, "d1/drone"),
                             "scheduler": SchedulerHandle(actor, "d1/scheduler")}}, port=0, token=TOKEN).start()
    try:
        assert len(_routes(srv)) >= 6, _routes(srv)
        assert _answers_200(srv.port, "/drones/d1")
        os.kill(pid, signal.SIGSTOP)  # the actor's process stops answering (as a hung or restarting one)
        try:
            for _ in range(200):  # the signal is delivered asynchronously: until the kernel says stopped
                if _process_state(pid) == "T":
                    break
                time.sleep(0.05)
            assert _process_state(pid) == "T"
            _all_503(srv, "stopped", still=lambda: _process_state(pid) == "T")
        finally:
            os.kill(pid, signal.SIGCONT)
        assert _actor_answers(actor) or _actor_answers(actor)  # continued: it answers its own calls again
        for method, path, body in _routes(srv):
            assert _answers_200(srv.port, path, method=method, body=body), (method, path)  # back
        ray.kill(actor, no_restart=True)  # gone for good
        for _ in range(240):  # ray.kill is asynchronous: wait until the actor is seen dead
            try:
                ray.get(actor.pid.remote(), timeout=30)
            except ray.exceptions.RayActorError:
                break
            time.sleep(0.5)
        else:
            pytest.fail("the killed actor still answers")
        _all_503(srv, "dead")
    finally:
        srv.stop()


def _answers_200(port: int, path: str, tries: int = 120, method: str = "GET", body: bytes | None = None) -> bool:
    """Whether ``method`` ``path`` comes back 200 within ``tries`` requests (0.5 s apart), every other answer being
    a 503 with ``Retry-After: 1`` (AssertionError otherwise)."""
    for _ in range(tries):
        status, out, headers = _send(port, method, path, body)
        if status == 200:
            return True
        assert status == 503 and headers.get("retry-after") == "1", (status, out)
        time.sleep(0.5)
    return False
