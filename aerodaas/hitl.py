"""Human-in-the-loop (HITL) HTTP API: a remote user steers running missions.

Built with FastAPI (request validation with the same pydantic models as the rest of AeroDaaS, automatic 422
responses that name the bad field, OpenAPI docs at ``/docs``) served by uvicorn in a daemon thread of the
driver process, which already holds the drone and scheduler actor handles. We chose this over a Ray Serve
deployment because Serve starts a controller and proxy actors (~2 more Ray worker processes, ~170 MB) for
a handful of low-rate requests per mission.

Every request needs ``Authorization: Bearer <token>``; the token is given in ``environment.json``
(``hitl.token``) or generated at start and printed once. A missing or wrong token gets 401, a malformed
request or one outside the safety limits 422, an unknown drone 404, and none of them change anything.
Loopback-only (127.0.0.1) unless ``hitl.host`` says otherwise.

Endpoints (JSON):

* ``GET  /drones``                      every drone: state, position (ENU m), battery %, queued navigation
* ``GET  /drones/{id}``                 one drone
* ``POST /drones/{id}/waypoints``       ``{"waypoints": [{"x", "y", "z", "hover_duration"?, "id"?, ...}],
  "index"?: int, "priority"?: int, "scheduling_type"?: "UNORDERED" | "ORDERED"}`` -> the new queue
* ``POST /drones/{id}/clear``           ``{"priority"?: int}`` abort queued navigation (never resumes)
* ``POST /drones/{id}/pause`` / ``resume``

The connection (url and token) is also written to ``$AERODAAS_STATE_DIR/hitl.json`` (default
``~/.aerodaas``; mode 0600) while the server runs, so ``aerodaas inject`` finds it without flags.
"""
from __future__ import annotations

import itertools
import json
import os
import secrets
import threading
import time
from pathlib import Path
from typing import Any

from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field

from .models import AeroNavigation, NavigationType, SchedulingType, Waypoint

__all__ = ["HitlServer", "state_file", "WaypointIn", "AddWaypointsRequest"]


def state_file() -> Path:
    """Where a running server publishes its url and token: ``$AERODAAS_STATE_DIR/hitl.json``."""
    return Path(os.environ.get("AERODAAS_STATE_DIR", Path.home() / ".aerodaas")) / "hitl.json"


class WaypointIn(Waypoint):
    """A waypoint in a request: a :class:`aerodaas.models.Waypoint` (same fields and checks) whose ``id`` is
    optional (the server assigns ``hitl<N>``). ``x``/``y``/``z`` are ENU metres from home (or lat/lon/alt with
    ``waypoint_type="absolute"``)."""

    id: str | None = Field(default=None, min_length=1)


class AddWaypointsRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    waypoints: list[WaypointIn] = Field(min_length=1)
    index: int | None = Field(default=None, ge=0)
    priority: int | None = Field(default=None, ge=0)
    scheduling_type: SchedulingType = SchedulingType.UNORDERED


class ClearRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    priority: int | None = Field(default=None, ge=0)


class HitlServer:
    """The HITL API for the drones of one run. ``drones``: robot id -> {"drone": handle of the drone component,
    "scheduler": handle of its trajectory-scheduler component} (``h.method.remote(...)`` handles). ``start()`` returns once the server accepts connections."""

    def __init__(self, drones: dict[str, dict], host: str = "127.0.0.1", port: int = 8470,
                 token: str | None = None) -> None:
        self.drones = drones
        self.host, self.port = host, port
        self.token = token or secrets.token_urlsafe(24)
        self.generated_token = token is None
        self._ids = itertools.count(1)
        self._server = None
        self._thread: threading.Thread | None = None
        self.requests = 0
        self.app = self._build_app()

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    # ------------------------------------------------------------------ app
    def _build_app(self):
        import ray

        from .safety import SafetyViolation

        app = FastAPI(title="AeroDaaS human-in-the-loop API", version="1")
        server = self

        def auth(request: Request) -> None:
            server.requests += 1
            h = request.headers.get("authorization", "")
            scheme, _, tok = h.partition(" ")
            if scheme.lower() != "bearer" or not secrets.compare_digest(tok.strip().encode(), server.token.encode()):
                raise HTTPException(401, "missing or invalid bearer token", headers={"WWW-Authenticate": "Bearer"})

        def drone(robot_id: str) -> dict:
            if robot_id not in server.drones:
                raise HTTPException(404, f"unknown drone {robot_id!r}; known: {sorted(server.drones)}")
            return server.drones[robot_id]

        def describe(robot_id: str) -> dict:
            h = drone(robot_id)
            st = ray.get(h["drone"].status.remote(), timeout=10)
            st["queue"] = ray.get(h["scheduler"].snapshot.remote(), timeout=10)
            return st

        @app.exception_handler(SafetyViolation)
        async def _safety(_req: Request, e: SafetyViolation) -> JSONResponse:
            return JSONResponse(status_code=422, content={"detail": [{
                "loc": ["body", "waypoints", e.item_id, e.field], "msg": str(e), "type": "safety_limit",
                "input": e.value}]})

        @app.get("/drones", dependencies=[Depends(auth)])
        def list_drones() -> list[dict]:
            return [describe(rid) for rid in server.drones]

        @app.get("/drones/{robot_id}", dependencies=[Depends(auth)])
        def get_drone(robot_id: str) -> dict:
            return describe(robot_id)

        @app.post("/drones/{robot_id}/waypoints", dependencies=[Depends(auth)])
        def add_waypoints(robot_id: str, req: AddWaypointsRequest) -> dict:
            h = drone(robot_id)
            queued = {i.get("id") for m in ray.get(h["scheduler"].snapshot.remote(), timeout=10) for i in m["items"]}
            wps = []
            for w in req.waypoints:
                wid = w.id or f"hitl{next(server._ids)}"
                while w.id is None and wid in queued:
                    wid = f"hitl{next(server._ids)}"
                if wid in queued:
                    raise HTTPException(422, f"waypoints: id {wid!r} is already queued")
                wps.append(Waypoint(**{**w.model_dump(), "id": wid}))
            nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, req.scheduling_type, name="hitl")
            try:
                out = ray.get(h["scheduler"].add_navigation.remote(nav, req.index, req.priority), timeout=10)
            except ray.exceptions.RayTaskError as e:
                cause = e.cause if hasattr(e, "cause") else None
                if isinstance(cause, SafetyViolation):
                    raise cause
                if isinstance(cause, (IndexError, ValueError, TypeError)):
                    raise HTTPException(422, str(cause))
                raise
            return {"added": [w.id for w in wps], **out}

        @app.post("/drones/{robot_id}/clear", dependencies=[Depends(auth)])
        def clear(robot_id: str, req: ClearRequest | None = None) -> dict:
            h = drone(robot_id)
            ray.get(h["scheduler"].clear_navigation.remote(req.priority if req else None), timeout=10)
            return {"cleared": True, "queue": ray.get(h["scheduler"].snapshot.remote(), timeout=10)}

        @app.post("/drones/{robot_id}/pause", dependencies=[Depends(auth)])
        def pause(robot_id: str) -> dict:
            ray.get(drone(robot_id)["drone"].pause_mission.remote(), timeout=10)
            return {"paused": True}

        @app.post("/drones/{robot_id}/resume", dependencies=[Depends(auth)])
        def resume(robot_id: str) -> dict:
            ray.get(drone(robot_id)["drone"].resume_mission.remote(), timeout=10)
            return {"resumed": True}

        return app

    # ------------------------------------------------------------------ lifecycle
    def start(self, timeout: float = 10.0) -> "HitlServer":
        """Serve in a daemon thread; returns when listening (the real port is known then). Raises
        RuntimeError if the server could not start (e.g. the port is taken)."""
        import uvicorn

        config = uvicorn.Config(self.app, host=self.host, port=self.port, log_level="warning", access_log=False,
                                lifespan="off")
        self._server = uvicorn.Server(config)
        self._server.install_signal_handlers = lambda: None  # the driver keeps Ctrl-C
        self._thread = threading.Thread(target=self._server.run, name="aerodaas-hitl", daemon=True)
        self._thread.start()
        t0 = time.monotonic()
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() - t0 > timeout:
                raise RuntimeError(f"HITL API could not start on {self.host}:{self.port} (port in use?)")
            time.sleep(0.02)
        sock = self._server.servers[0].sockets[0]
        self.port = sock.getsockname()[1]
        f = state_file()
        f.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(f, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as fh:
            json.dump({"url": self.url, "token": self.token, "pid": os.getpid(), "drones": sorted(self.drones)}, fh)
        return self

    def stop(self) -> None:
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5)
        try:
            f = state_file()
            if f.is_file() and json.loads(f.read_text()).get("pid") == os.getpid():
                f.unlink()
        except (OSError, ValueError):
            pass


def request(method: str, path: str, body: Any = None, url: str | None = None, token: str | None = None,
            timeout: float = 10.0) -> tuple[int, Any]:
    """Minimal client (stdlib only): returns (HTTP status, decoded JSON). ``url``/``token`` default to
    ``$AERODAAS_HITL_URL``/``$AERODAAS_HITL_TOKEN``, then the running server's :func:`state_file`.
    Raises RuntimeError when no server can be found."""
    import urllib.error
    import urllib.request

    url = url or os.environ.get("AERODAAS_HITL_URL")
    token = token or os.environ.get("AERODAAS_HITL_TOKEN")
    if not url or not token:
        f = state_file()
        if not f.is_file():
            raise RuntimeError(f"no HITL server found: give --url and --token, set AERODAAS_HITL_URL/"
                               f"AERODAAS_HITL_TOKEN, or start a run with hitl enabled (writes {f})")
        info = json.loads(f.read_text())
        url, token = url or info["url"], token or info["token"]
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url.rstrip("/") + path, data=data, method=method,
                                 headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        raw = e.read()
        try:
            return e.code, json.loads(raw)
        except ValueError:
            return e.code, raw.decode(errors="replace")
    except urllib.error.URLError as e:
        raise RuntimeError(f"cannot reach the HITL API at {url}: {e.reason}") from None
