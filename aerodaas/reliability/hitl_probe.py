"""HITL API cases of ``python -m aerodaas.reliability``: the real FastAPI app under uvicorn on loopback, in front
of a real scheduler component (:class:`aerodaas.actors.drone.scheduler_component.SchedulerComponent`) and a stand-in
drone, called in-process (no Ray). Each row: what was sent, what came back, whether that is the documented answer.
A drone actor that does not answer (503) needs Ray: ``tests/safety/test_hitl_unreachable.py``."""
from __future__ import annotations

import http.client
import json
import os
import tempfile
import threading
from types import SimpleNamespace
from typing import Any

from aerodaas.actors.drone.scheduler_component import SchedulerComponent
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.schedulers import NearestNeighborScheduler
from aerodaas.tools.hitl import HitlServer

__all__ = ["run_hitl_cases"]

_TOKEN = "p" * 24


class _Ref:
    def __init__(self, fn: Any, args: tuple) -> None:
        self.value, self.error = None, None
        try:
            self.value = fn(*args)
        except Exception as e:  # noqa: BLE001 - re-raised by _get
            self.error = e


def _get(ref: _Ref, timeout: float | None = None) -> Any:
    if ref.error is not None:
        raise ref.error
    return ref.value


class _Handle:
    def __init__(self, obj: Any) -> None:
        self._o = obj

    def __getattr__(self, name: str) -> Any:
        fn = getattr(self._o, name)
        return SimpleNamespace(remote=lambda *a: _Ref(fn, a))


class _Drone:
    def status(self) -> dict:
        return {"state": "NAVIGATING", "position": [0.0, 0.0, 2.0], "visited": 0}


def _send(port: int, method: str, path: str, body: Any = None, chunked: bool = False) -> int:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    c.request(method, path, body=body, encode_chunked=chunked,
              headers={"Authorization": f"Bearer {_TOKEN}", "Content-Type": "application/json"})
    r = c.getresponse()
    r.read()
    c.close()
    return r.status


def run_hitl_cases() -> list[dict[str, Any]]:
    """Rows ``{"kind": "HITL API", "name", "refused", "message"}`` (``refused``: answered as documented)."""
    rows: list[dict[str, Any]] = []

    def row(name: str, ok: bool, msg: str) -> None:
        rows.append({"kind": "HITL API", "name": name, "refused": ok, "message": msg})

    for tok in (" " * 16, "abcdefgh ijklmnop"):
        try:
            HitlServer({}, port=0, token=tok, get=_get)
            row(f"token {tok!r}", False, "accepted")
        except ValueError as e:
            row(f"token {tok!r}", True, str(e))
    state_dir = tempfile.mkdtemp(prefix="aerodaas-hitl-probe-")
    old = os.environ.get("AERODAAS_STATE_DIR")
    os.environ["AERODAAS_STATE_DIR"] = state_dir
    sched = SchedulerComponent(None, "d1/scheduler", "d1", NearestNeighborScheduler(start=(0, 0, 2)), None, 0,
                               robot_cfg={"id": "d1"})
    srv = HitlServer({"d1": {"drone": _Handle(_Drone()), "scheduler": _Handle(sched)}}, port=0, token=_TOKEN,
                     get=_get).start()
    try:
        real_snapshot = sched.snapshot

        def slow_snapshot() -> list:  # as a remote call under load: widens the check-then-add window
            out = real_snapshot()
            threading.Event().wait(0.02)
            return out

        sched.snapshot = slow_snapshot
        results: list[int] = []
        barrier = threading.Barrier(64)

        def post() -> None:
            barrier.wait()
            results.append(_send(srv.port, "POST", "/drones/d1/waypoints",
                                 json.dumps({"waypoints": [{"id": "same", "x": 2, "y": 2, "z": 2}]})))

        threads = [threading.Thread(target=post) for _ in range(64)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)
        sched.snapshot = real_snapshot
        n = results.count(200)
        row("64 concurrent POSTs with one waypoint id", n == 1 and len(results) == 64,
            f"{n} accepted, {results.count(422)} refused 422 (already queued)")
        sched.clear_navigation()
        st = _send(srv.port, "POST", "/drones/d1/waypoints", (b"x" * 65536 for _ in range(6)), chunked=True)
        row("chunked body of 384 KiB", st == 413, f"HTTP {st}")
        st = _send(srv.port, "POST", "/drones/d1/waypoints",
                   json.dumps({"waypoints": [{"x": 1, "y": 0, "z": 2, "speed": 1e-300}]}))
        row("waypoint speed 1e-300", st == 422, f"HTTP {st}")
        sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="s1", x=-3, y=-3, z=2)],
                                            SchedulingType.ORDERED, name="survey"))
        for body in (b"null", b"{}"):
            st = _send(srv.port, "POST", "/drones/d1/clear", body)
            row(f"clear with body {body.decode()}", st == 422 and len(sched.snapshot()) == 1,
                f"HTTP {st}, pre-planned survey {'kept' if sched.snapshot() else 'CLEARED'}")
        st = _send(srv.port, "POST", "/drones/d1/clear", b'{"scope": "injected"}')
        row("clear scope injected keeps the pre-planned survey", st == 200 and len(sched.snapshot()) == 1,
            f"HTTP {st}, survey {'kept' if sched.snapshot() else 'CLEARED'}")
    finally:
        srv.stop()
        if old is None:
            os.environ.pop("AERODAAS_STATE_DIR", None)
        else:
            os.environ["AERODAAS_STATE_DIR"] = old
    return rows
