"""Human-in-the-loop (HITL) HTTP API: a remote user steers running missions.

Built with FastAPI (request validation with the same pydantic models as the rest of AeroDaaS, 422 responses that
name the bad field; the OpenAPI docs ``/docs`` and ``/openapi.json`` only with ``hitl.docs: true``, and then behind
the token) served by uvicorn in a daemon thread of the
driver process, which already holds the drone and scheduler actor handles. We chose this over a Ray Serve
deployment because Serve starts a controller and proxy actors (~2 more Ray worker processes, ~170 MB) for
a handful of low-rate requests per mission.

Every request needs ``Authorization: Bearer <token>``; the token is given in ``environment.json``
(``hitl.token``) or generated at start, and never printed (see the state file below). A missing or wrong token gets
401, a malformed
request or one outside the safety limits 422 (a waypoint id already queued too: checked and added under one
lock per drone, so of concurrent requests with the same id exactly one is accepted) (NaN/Infinity, strings for numbers, unknown keys, ids over
:data:`MAX_ID_CHARS` characters, more than :data:`MAX_WAYPOINTS_PER_REQUEST` waypoints, a planned tour whose leg
crosses the geofence), a body over :data:`MAX_BODY_BYTES` 413 (declared or chunked), an unknown drone 404, a drone
actor that does not answer within :data:`CALL_TIMEOUT_S` (stopped, restarting, gone) 503 with ``Retry-After``, and
none of them change anything. A token given to the server must be an RFC 6750 ``b64token`` of at least 16
characters (no blanks).
Loopback-only (127.0.0.1) unless ``hitl.host`` says otherwise; off loopback it serves HTTPS with ``hitl.tls_cert`` /
``hitl.tls_key`` (or ``--tls-cert`` / ``--tls-key``; uvicorn over Python's :mod:`ssl`) and refuses plain HTTP unless
``hitl.insecure`` / ``--insecure`` says so (:mod:`aerodaas.clusters.tls`, checked before Ray starts). The token is never
printed: it is in the state file below, readable by its owner only.

Endpoints (JSON):

* ``GET  /drones``                      every drone: state, position (ENU m), battery %, queued navigation
* ``GET  /drones/{id}``                 one drone
* ``POST /drones/{id}/waypoints``       ``{"waypoints": [{"x", "y", "z", "hover_duration"?, "id"?, ...}],
  "index"?: int, "priority"?: int, "scheduling_type"?: "UNORDERED" | "ORDERED"}`` -> the new queue
* ``POST /drones/{id}/clear``           ``{"scope": "injected" | "all", "priority"?: int}`` abort queued navigation
  (never resumes): ``injected`` only what was added through this API, ``all`` the pre-planned mission too (the
  mission is then ``incomplete``, never a success). The scope is required: an empty or null body is 422
* ``POST /drones/{id}/pause`` / ``resume``

The connection (url, token and, with TLS, the certificate to trust: ``cafile``) is written to
``$AERODAAS_STATE_DIR/hitl.json`` (default ``~/.aerodaas``; mode 0600, created so: never readable by others, not even
for a moment) while the server runs, so ``aerodaas inject`` finds it without flags.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import re
import secrets
import threading
import time
from typing import Any, Literal

from fastapi import Depends, FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from aerodaas.clusters.tls import ServeAccess, write_private_json
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.navigation.safety import SafetyViolation
# the client (``aerodaas inject``) lives in its own module, without FastAPI; these names stay importable from here
from aerodaas.tools.hitl_client import state_file

__all__ = ["HitlServer", "WaypointIn", "AddWaypointsRequest"]


#: limits of one request: body bytes (413 beyond), waypoints per request (422 beyond; the robot's
#: ``max_waypoints_per_request`` and ``max_queued_items`` apply too), characters of a waypoint id
MAX_BODY_BYTES = 256 * 1024
MAX_WAYPOINTS_PER_REQUEST = 1000
MAX_ID_CHARS = 64
#: seconds a request waits for a drone or scheduler actor's answer before it is 503 (the whole request stays well
#: within 2 s)
CALL_TIMEOUT_S = 1.5
#: a bearer token (RFC 6750 section 2.1 ``b64token``), at least 16 characters
TOKEN_RE = re.compile(r"[A-Za-z0-9\-._~+/]{16,256}=*")


class WaypointIn(Waypoint):
    """A waypoint in a request: a :class:`aerodaas.model.types.Waypoint` (same fields and checks) whose ``id`` is
    optional (the server assigns ``hitl<N>``) and at most :data:`MAX_ID_CHARS` printable characters. ``x``/``y``/``z``
    are ENU metres from home (or lat/lon/alt with ``waypoint_type="absolute"``). Numbers must be JSON numbers
    (strict: ``"3"`` and ``true`` are refused) and finite."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    id: str | None = Field(default=None, min_length=1, max_length=MAX_ID_CHARS, pattern=r"^[\x21-\x7e]+$")


class AddWaypointsRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    waypoints: list[WaypointIn] = Field(min_length=1, max_length=MAX_WAYPOINTS_PER_REQUEST)
    index: int | None = Field(default=None, ge=0, le=1_000_000)
    priority: int | None = Field(default=None, ge=0, le=1_000_000)
    scheduling_type: SchedulingType = Field(default=SchedulingType.UNORDERED, strict=False)


class ClearRequest(BaseModel):
    """``scope``: ``"injected"`` (only navigation added through the HITL API) or ``"all"`` (the pre-planned mission
    too); required. ``priority``: only missions at this priority."""

    model_config = ConfigDict(extra="forbid", strict=True)
    scope: Literal["injected", "all"]
    priority: int | None = Field(default=None, ge=0, le=1_000_000)


def _json_safe(v: Any, depth: int = 0) -> Any:
    """An echo of request input that JSON can carry: non-finite floats as strings, long strings and deep or long
    containers cut (an error reply never fails to serialise, and never echoes a megabyte back)."""
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)
    if isinstance(v, str):
        return v if len(v) <= 80 else v[:77] + "..."
    if depth > 3:
        return "..."
    if isinstance(v, dict):
        return {str(k)[:80]: _json_safe(x, depth + 1) for k, x in list(v.items())[:20]}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x, depth + 1) for x in list(v)[:20]]
    if v is None or isinstance(v, (bool, int, float)):
        return v
    return repr(v)[:80]


class _BodyLimit:
    """ASGI middleware: a request body over ``limit`` bytes is answered 413 before it is read into memory or
    parsed (declared Content-Length, or counted while streaming)."""

    def __init__(self, app: Any, limit: int) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        declared = dict(scope.get("headers") or []).get(b"content-length")
        too_big = False
        try:
            too_big = declared is not None and int(declared) > self.limit
        except ValueError:
            too_big = True
        if too_big:
            return await self._reject(send)
        if declared is None:  # chunked (no length declared): read it here, at most limit + 1 bytes, then decide
            parts, seen, more = [], 0, True
            while more:
                msg = await receive()
                if msg["type"] != "http.request":
                    return await self.app(scope, receive, send)  # the client went away
                parts.append(msg.get("body", b""))
                seen += len(parts[-1])
                if seen > self.limit:
                    return await self._reject(send)
                more = msg.get("more_body", False)
            body, done = b"".join(parts), False

            async def replay() -> dict:
                nonlocal done
                if not done:
                    done = True
                    return {"type": "http.request", "body": body, "more_body": False}
                return await receive()

            return await self.app(scope, replay, send)
        seen = 0

        async def limited() -> dict:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > self.limit:
                    raise _TooLarge()
            return msg

        try:
            await self.app(scope, limited, send)
        except _TooLarge:
            await self._reject(send)

    async def _reject(self, send: Any) -> None:
        body = json.dumps({"detail": f"request body larger than {self.limit} bytes"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


class _TooLarge(Exception):
    pass


def _add_error_handlers(app: Any) -> None:
    """Error answers as JSON: an HTTP error (an undecodable body is 422 like every malformed one), a request that
    does not validate (at most 20 errors), and a waypoint outside the safety limits (422, ``safety_limit``)."""
    @app.exception_handler(StarletteHTTPException)
    async def _http(_req: Request, e: StarletteHTTPException) -> JSONResponse:
        # FastAPI answers an undecodable body 400; a malformed body is 422 like every other one
        code = 422 if e.status_code == 400 else e.status_code
        return JSONResponse(status_code=code, content={"detail": _json_safe(e.detail)}, headers=e.headers)

    @app.exception_handler(RequestValidationError)
    async def _invalid(_req: Request, e: RequestValidationError) -> JSONResponse:
        errors = [{"loc": list(d.get("loc", [])), "msg": str(d.get("msg", ""))[:300], "type": d.get("type"),
                   "input": _json_safe(d.get("input"))} for d in e.errors()[:20]]
        return JSONResponse(status_code=422, content={"detail": errors})

    @app.exception_handler(SafetyViolation)
    async def _safety(_req: Request, e: SafetyViolation) -> JSONResponse:
        return JSONResponse(status_code=422, content={"detail": [{
            "loc": ["body", "waypoints", str(e.item_id)[:80], e.field], "msg": str(e)[:500], "type": "safety_limit",
            "input": _json_safe(e.value)}]})


class HitlServer:
    """The HITL API for the drones of one run. ``drones``: robot id -> {"drone": handle of the drone component,
    "scheduler": handle of its trajectory-scheduler component} (``h.method.remote(...)`` handles). ``start()`` returns
    once the server accepts connections. ``cert_file`` / ``key_file``: PEM certificate and key, served as HTTPS
    (checked first: :func:`aerodaas.clusters.tls.check_tls_files`). The constructor applies the exposure rule of
    every server (:func:`aerodaas.clusters.tls.check_exposure`): bound off loopback, HTTPS or ``insecure=True``
    (plain HTTP, then :attr:`insecure` is True: what the run summary repeats). Raises ``ValueError`` naming the
    parameter (a bad token, TLS files or exposure)."""

    def __init__(self, drones: dict[str, dict], host: str = "127.0.0.1", port: int = 8470,
                 token: str | None = None, docs: bool = False, get: Any = None, cert_file: str | None = None,
                 key_file: str | None = None, insecure: bool = False) -> None:
        self.drones = drones
        self.docs = docs  # /docs and /openapi.json: off unless asked for, and then behind the token
        self._get = get  # how a call's result is awaited (default ray.get; tests pass a local one)
        self.host, self.port = host, port
        self.cert_file, self.key_file = cert_file, key_file
        if token is not None and not TOKEN_RE.fullmatch(token):
            raise ValueError("hitl.token: 16 to 256 characters of A-Z a-z 0-9 - . _ ~ + / (then '=' padding; RFC 6750 "
                             "section 2.1), no blanks")
        self.token = token or secrets.token_urlsafe(24)
        self.access = ServeAccess(cert_file, key_file, self.token, bool(insecure))
        self.access.check(host, f"HitlServer(host={host!r})", "cert_file", "key_file", "insecure=True", "token")
        self._locks = {rid: threading.Lock() for rid in drones}  # one add (check + queue) at a time per drone
        self.generated_token = token is None
        self._ids = itertools.count(1)
        self._server = None
        self._thread: threading.Thread | None = None
        self.requests = 0
        self.app = self._build_app()

    @property
    def insecure(self) -> bool:
        """Whether this API serves plain HTTP off loopback (``insecure=True``): what the run summary repeats."""
        return self.access.clear_text_off_loopback(self.host)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.cert_file else 'http'}://{host}:{self.port}"

    @property
    def local_url(self) -> str:
        """:attr:`url` as a client on this machine reaches it: a wildcard host (``0.0.0.0``, ``::``) becomes
        ``localhost`` (the name a certificate for local use carries; give ``aerodaas inject --url`` the name of
        yours otherwise). What the state file hands to ``aerodaas inject``."""
        if self.host in ("0.0.0.0", "::", ""):
            return f"{'https' if self.cert_file else 'http'}://localhost:{self.port}"
        return self.url

    # ------------------------------------------------------------------ app
    def _build_app(self):
        """The FastAPI app: its error answers (:func:`_add_error_handlers`), the drone routes behind the bearer
        token and, with ``hitl.docs``, the guarded documentation."""
        # no unauthenticated documentation: /docs, /redoc and /openapi.json are off (see ``docs`` for the guarded ones)
        app = FastAPI(title="AeroDaaS human-in-the-loop API", version="1", docs_url=None, redoc_url=None,
                      openapi_url=None)
        app.add_middleware(_BodyLimit, limit=MAX_BODY_BYTES)
        _add_error_handlers(app)
        self._add_routes(app)
        if self.docs:  # hitl.docs: true: the documentation, behind the same bearer token as everything else
            @app.get("/openapi.json", dependencies=[Depends(self._auth)], include_in_schema=False)
            def openapi() -> dict:
                return app.openapi()

            @app.get("/docs", dependencies=[Depends(self._auth)], include_in_schema=False)
            def docs():
                return get_swagger_ui_html(openapi_url="/openapi.json", title=app.title)

        return app

    def _call(self, method: Any, *args: Any) -> Any:
        """Call a component method and wait at most :data:`CALL_TIMEOUT_S`; a remote exception is re-raised as
        its cause; an actor that does not answer (stopped, restarting, dead) is 503."""
        import ray  # lazy: CLI start-up (`aerodaas inject` imports this module and runs without Ray)

        get = self._get or ray.get
        try:
            return get(method.remote(*args), timeout=CALL_TIMEOUT_S)
        except ray.exceptions.RayTaskError as e:
            cause = getattr(e, "cause", None)
            if isinstance(cause, Exception):
                raise cause from None
            raise HTTPException(503, f"the drone's actor failed: {str(e).splitlines()[0][:200]}",
                                headers={"Retry-After": "1"}) from None
        except (ray.exceptions.GetTimeoutError, ray.exceptions.RayActorError, ray.exceptions.ActorUnavailableError,
                ray.exceptions.RayError, TimeoutError) as e:
            raise HTTPException(503, f"the drone's actor does not answer within {CALL_TIMEOUT_S:g} s (stopped, "
                                f"restarting or gone: {type(e).__name__}); retry later",
                                headers={"Retry-After": "1"}) from None

    def _auth(self, request: Request) -> None:
        """The bearer token (401 without it); counts the request."""
        self.requests += 1
        h = request.headers.get("authorization", "")
        scheme, _, tok = h.partition(" ")
        if scheme.lower() != "bearer" or not secrets.compare_digest(tok.strip().encode(), self.token.encode()):
            raise HTTPException(401, "missing or invalid bearer token", headers={"WWW-Authenticate": "Bearer"})

    def _drone(self, robot_id: str) -> dict:
        if robot_id not in self.drones:
            raise HTTPException(404, f"unknown drone {robot_id!r}; known: {sorted(self.drones)}")
        return self.drones[robot_id]

    def _describe(self, robot_id: str) -> dict:
        h = self._drone(robot_id)
        st = self._call(h["drone"].status)
        st["queue"] = self._call(h["scheduler"].snapshot)
        return st

    def _add_routes(self, app: Any) -> None:
        """The drone routes: list, get, add waypoints, clear, pause, resume."""
        call, drone, guarded = self._call, self._drone, [Depends(self._auth)]

        @app.get("/drones", dependencies=guarded)
        def list_drones() -> list[dict]:
            return [self._describe(rid) for rid in self.drones]

        @app.get("/drones/{robot_id}", dependencies=guarded)
        def get_drone(robot_id: str) -> dict:
            return self._describe(robot_id)

        @app.post("/drones/{robot_id}/waypoints", dependencies=guarded)
        def add_waypoints(robot_id: str, req: AddWaypointsRequest) -> dict:
            h = drone(robot_id)
            lock = self._locks.setdefault(robot_id, threading.Lock())
            if not lock.acquire(timeout=10.0):
                raise HTTPException(503, "too many concurrent requests for this drone; retry later",
                                    headers={"Retry-After": "1"})
            try:  # the id check and the add are one step: of concurrent requests with one id, one is accepted
                return self._add(h, req)
            finally:
                lock.release()

        @app.post("/drones/{robot_id}/clear", dependencies=guarded)
        def clear(robot_id: str, req: ClearRequest) -> dict:
            h = drone(robot_id)
            out = call(h["scheduler"].clear_navigation, req.priority, req.scope, "hitl")
            return {"cleared": True, "scope": req.scope, **(out or {}), "queue": call(h["scheduler"].snapshot)}

        @app.post("/drones/{robot_id}/pause", dependencies=guarded)
        def pause(robot_id: str) -> dict:
            call(drone(robot_id)["drone"].pause_mission)
            return {"paused": True}

        @app.post("/drones/{robot_id}/resume", dependencies=guarded)
        def resume(robot_id: str) -> dict:
            call(drone(robot_id)["drone"].resume_mission)
            return {"resumed": True}

    def _add(self, h: dict, req: AddWaypointsRequest) -> dict:
        """Queue the request's waypoints on drone ``h`` (ids given or ``hitl<n>``, none already queued)."""
        queued = {i.get("id") for m in self._call(h["scheduler"].snapshot) for i in m["items"]}
        wps = []
        for w in req.waypoints:
            wid = w.id or f"hitl{next(self._ids)}"
            while w.id is None and wid in queued:
                wid = f"hitl{next(self._ids)}"
            if wid in queued:
                raise HTTPException(422, f"waypoints: id {wid!r} is already queued")
            wps.append(Waypoint(**{**w.model_dump(), "id": wid}))
        ids = [w.id for w in wps]
        if len(set(ids)) != len(ids):
            raise HTTPException(422, f"waypoints: duplicate ids {sorted({i for i in ids if ids.count(i) > 1})}")
        try:
            nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, req.scheduling_type, name="hitl")
            out = self._call(h["scheduler"].add_navigation, nav, req.index, req.priority)
        except SafetyViolation:
            raise
        except (IndexError, ValueError, TypeError) as e:
            raise HTTPException(422, str(e)[:500]) from None
        return {"added": ids, **out}

    # ------------------------------------------------------------------ lifecycle
    def start(self, timeout: float = 10.0) -> "HitlServer":
        """Serve in a daemon thread; returns when listening (the real port is known then). Raises
        RuntimeError if the server could not start (e.g. the port is taken)."""
        import uvicorn  # lazy: heavy dependency (uvicorn)

        tls = {"ssl_certfile": self.cert_file, "ssl_keyfile": self.key_file} if self.cert_file else {}
        config = uvicorn.Config(self.app, host=self.host, port=self.port, log_level="warning", access_log=False,
                                lifespan="off", **tls)
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

        write_private_json(state_file(), {"url": self.local_url, "token": self.token, "pid": os.getpid(),
                                          "drones": sorted(self.drones),
                                          "cafile": os.path.abspath(self.cert_file) if self.cert_file else None})
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
