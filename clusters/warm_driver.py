"""The warm driver of ``aerodaas up``: a pre-imported process that forks each attached ``aerodaas run``.

Building an application in a fresh driver process starts with importing Ray, NumPy, pydantic, OpenCV and the
framework, about a second of CPU on a small machine, before anything of the run itself happens. The daemon of
``aerodaas up`` (:mod:`aerodaas.clusters.persistent`) therefore starts this server (``python -P -m
aerodaas.clusters.warm_driver SOCKET``), a fork server (zygote) that imports :data:`PRELOAD` once, without calling
``ray.init``, and listens on the Unix socket :func:`aerodaas.clusters.warm_client.socket_path` (mode 0600 in a 0700
folder: only the same user connects; the peer's uid is checked as well, ``SO_PEERCRED``).

For each request of :func:`aerodaas.clusters.warm_client.delegate` it forks a child that becomes the client's
command: its own session (``setsid``), the client's file descriptors as 0, 1 and 2 with standard streams set up as
the client's interpreter set up its own, the client's working folder, environment, ``sys.argv``, ``sys.path``,
umask, niceness, CPU affinity, resource limits and ignored signals, Python's default signal handlers, a re-seeded
NumPy global generator. The child then runs the command line's ``main`` (:data:`COMMAND_LINE`, named rather than
imported: this module sits below the command line's layer) and ends as the console script ends
(``sys.exit``: exit handlers, stream flush). The server reports the child's end to the client (exit code or
signal) and sends SIGTERM to a child whose client went away.

The server refuses (the client runs the command itself) when the request would not behave as a fresh process:
another interpreter or import path, a difference in an environment variable read at import time
(:data:`IMPORT_TIME_ENV`), a framework module edited since the server started (it then starts itself afresh once
its children have ended), a resource limit or niceness the server cannot grant.

Fork safety: at fork the server has one thread. :func:`preload` checks that no import started a Python thread and
that no import after NumPy and OpenCV started a native one (their OpenBLAS pools stop themselves before a fork,
``pthread_atfork``); onnxruntime (a native thread at import) and SciPy stay out of :data:`PRELOAD`. gRPC starts with
``ray.init``, which only the child calls.
"""
from __future__ import annotations

import gc
import importlib
import json
import locale
import os
import resource
import selectors
import signal
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass, field

from aerodaas.clusters.warm_client import RLIMITS, socket_path
from aerodaas.clusters.warm_pool import code_fingerprint

__all__ = ["COMMAND_LINE", "IMPORT_TIME_ENV", "PRELOAD", "ForkSafetyError", "main", "preload", "serve"]

#: imported before the fork-safety baseline: the libraries whose OpenBLAS thread pools are fork-safe
BASELINE = ("numpy", "cv2")
#: what an attached ``aerodaas run`` imports to build and start its application (the rest comes with them);
#: checked to start no thread
PRELOAD = ("pydantic", "ray", "ray.util.state", "aerodaas.cli", "aerodaas.commands.run", "aerodaas.runtime.fly",
           "aerodaas.app.api", "aerodaas.runtime.app_loader", "aerodaas.actors.builtin.catalogue",
           "aerodaas.actors.builtin.handles", "aerodaas.actors.host.drone_actor", "aerodaas.actors.host.analytics_actor",
           "aerodaas.actors.recording.actor", "aerodaas.actors.cloud.executor", "aerodaas.actors.host.remote",
           "aerodaas.actors.sensors.frame_sources", "aerodaas.backends.sim", "aerodaas.perception.model_files",
           "aerodaas.perception.model_meta", "aerodaas.video.discovery", "aerodaas.clusters.local",
           "aerodaas.clusters.loopback", "aerodaas.clusters.warm_pool")
#: the command line the child runs: its ``main(argv, own_process=True)``, as the ``aerodaas`` console script does
COMMAND_LINE = "aerodaas.cli"
#: environment variables (prefixes) that libraries read when imported: a request that differs here is refused
IMPORT_TIME_ENV = ("RAY_", "PYTHON", "LD_", "OMP_", "OPENBLAS_", "MKL_", "GRPC_", "OPENCV_", "MALLOC_")
#: the server waits this long for its children after SIGTERM before it exits
STOP_GRACE_S = 10.0


class ForkSafetyError(RuntimeError):
    """An import of :data:`PRELOAD` started a thread: forking would copy a process with a thread stopped mid-way."""


def _native_threads() -> int:
    return len(os.listdir("/proc/self/task"))


def preload(names: tuple[str, ...] = PRELOAD, baseline: tuple[str, ...] = BASELINE) -> None:
    """Import ``baseline`` then ``names`` (a name of ``aerodaas.*`` that does not import is skipped: the child's
    own import then reports it as before), resolve the public API (``from aerodaas import *``), then move every
    object out of the cyclic collector's sight (``gc.freeze``, as CPython's documentation advises before forking).
    Raises :class:`ForkSafetyError` naming the import that started a Python thread, or a native thread after the
    baseline."""
    for name in baseline:
        importlib.import_module(name)
    base = _native_threads()
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError:
            if not name.startswith("aerodaas."):
                raise
        if threading.active_count() != 1 or _native_threads() != base:
            raise ForkSafetyError(f"importing {name} started a thread ({threading.active_count()} Python, "
                                  f"{_native_threads()} native, {base} before): it cannot be preloaded")
    api = sys.modules.get("aerodaas")
    for name in getattr(api, "__all__", ()):
        getattr(api, name, None)
    gc.collect()
    gc.freeze()


@dataclass
class _Run:
    """A forked run: its pid, the client's connection and the pid's file descriptor (readable at its end)."""
    pid: int
    conn: socket.socket
    pidfd: int


@dataclass
class _Server:
    path: str
    listener: socket.socket
    sel: selectors.BaseSelector
    env: dict[str, str]
    env_delta: dict[str, str | None]
    fingerprint: str
    path_at_start: list[str]
    runs: dict[int, _Run] = field(default_factory=dict)
    stopping: list[int] = field(default_factory=list)
    stale: list[str] = field(default_factory=list)


def _listen(path: str) -> socket.socket:
    """Bind ``path`` (a stale file there removed) in a 0700 folder, the socket file 0600."""
    folder = os.path.dirname(path)
    os.makedirs(folder, mode=0o700, exist_ok=True)
    if os.stat(folder).st_uid != os.getuid():
        raise PermissionError(f"{folder} belongs to another user")
    os.chmod(folder, 0o700)
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    old = os.umask(0o177)
    try:
        s.bind(path)
    finally:
        os.umask(old)
    os.chmod(path, 0o600)
    s.listen(16)
    return s


def _import_time_env(env: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if k.startswith(IMPORT_TIME_ENV)}


def _refusal(srv: _Server, req: dict) -> str | None:
    """Why this server cannot run ``req`` as a fresh process would, or None."""
    if req.get("exe") != sys.executable or list(req.get("path") or [])[1:] != srv.path_at_start:
        return "another interpreter or import path"
    mine, theirs = _import_time_env(srv.env), _import_time_env(req.get("env") or {})
    if mine != theirs:
        names = sorted(k for k in mine.keys() | theirs.keys() if mine.get(k) != theirs.get(k))
        return f"environment variables read at import differ: {', '.join(names)}"
    if req.get("nice", 0) < os.getpriority(os.PRIO_PROCESS, 0):
        return "a higher priority than the server's"
    for name, (soft, hard) in (req.get("rlimits") or {}).items():
        if name not in RLIMITS:
            continue
        have = resource.getrlimit(getattr(resource, name))[1]
        if have != resource.RLIM_INFINITY and (hard == resource.RLIM_INFINITY or hard > have):
            return f"{name} above the server's"
    if srv.stale:
        return "framework code edited since the server started"
    if code_fingerprint() != srv.fingerprint:
        srv.stale.append("code")
        return "framework code edited since the server started"
    return None


def _reopen_streams(streams: list) -> None:
    """``sys.stdin``/``stdout``/``stderr`` on descriptors 0, 1, 2 with the client's encoding, errors and
    buffering (``[encoding, errors, line_buffering, write_through]`` each)."""
    for fd, name, mode in ((0, "stdin", "r"), (1, "stdout", "w"), (2, "stderr", "w")):
        enc, errors, line, through = streams[fd]
        f = open(fd, mode, encoding=enc, errors=errors, closefd=False,  # noqa: SIM115 - the process's own stream
                 buffering=-1, newline=None if fd == 0 else "\n")
        if fd:
            f.reconfigure(line_buffering=line, write_through=through)
        setattr(sys, name, f)
        setattr(sys, f"__{name}__", f)


def _become(req: dict, fds: list[int], env_delta: dict[str, str | None]) -> None:
    """In the child: become the client's command (see the module's docstring)."""
    os.setsid()
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
    for fd in fds:
        if fd > 2:
            os.close(fd)
    _reopen_streams(req["streams"])
    os.chdir(req["cwd"])
    os.environ.clear()
    os.environ.update(req["env"])
    for k, v in env_delta.items():  # what the preloaded imports did to the environment
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    sys.argv[:] = req["argv"]
    sys.path[:] = req["path"][:1] + sys.path  # the client's first entry (its script's folder) on the server's
    os.umask(int(req["umask"]))
    os.setpriority(os.PRIO_PROCESS, 0, int(req["nice"]))
    os.sched_setaffinity(0, req["affinity"])
    for name, (soft, hard) in req["rlimits"].items():
        try:
            resource.setrlimit(getattr(resource, name), (soft, hard))
        except (ValueError, OSError, AttributeError):
            pass
    time.tzset()
    try:
        locale.setlocale(locale.LC_CTYPE, "")
    except Exception:  # noqa: BLE001 - the client's locale may not exist here: C as before
        pass
    signal.set_wakeup_fd(-1)
    for s in (signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGCHLD, signal.SIGWINCH):
        signal.signal(s, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    for s in req["ignored"]:
        signal.signal(s, signal.SIG_IGN)
    np = sys.modules.get("numpy")
    if np is not None:
        np.random.seed()  # the legacy global generator was seeded once, in the server


def _accept(srv: _Server) -> dict | None:
    """Take one request; in the forked child return it, in the server None."""
    conn, _ = srv.listener.accept()
    try:
        conn.settimeout(10.0)
        pid_uid_gid = struct.unpack("3i", conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, 12))
        if pid_uid_gid[1] != os.getuid():
            conn.close()
            return None
        data, fds, _flags, _addr = socket.recv_fds(conn, 1 << 20, 3)
    except (OSError, struct.error):
        conn.close()
        return None
    try:
        req = json.loads(data)
        why = "not three file descriptors" if len(fds) != 3 else _refusal(srv, req)
    except (ValueError, TypeError, KeyError, AttributeError) as e:
        why = f"bad request ({type(e).__name__})"
    if why:
        _close(fds)
        try:
            conn.send(json.dumps({"refused": why}).encode())
        except OSError:
            pass
        conn.close()
        print(f"aerodaas warm driver: refused a run: {why}", flush=True)
        return None
    for f in (sys.stdout, sys.stderr):
        f.flush()
    go_r, go_w = os.pipe()  # the child starts once its client has its pid: a client that gave up never sees it
    pid = os.fork()
    if pid == 0:
        os.close(go_w)
        if os.read(go_r, 1) != b"1":
            os._exit(0)
        os.close(go_r)
        srv.sel.close()
        for c in (srv.listener, conn, *(r.conn for r in srv.runs.values())):
            c.close()  # the socket objects, not their numbers: a number closed twice may be someone else's by then
        _close([r.pidfd for r in srv.runs.values()])
        srv.runs.clear()
        _become(req, fds, srv.env_delta)
        return req
    _close(fds)
    print(f"aerodaas warm driver: run {pid} for client {req.get('client')}: {' '.join(req['argv'][1:])}", flush=True)
    pidfd = os.pidfd_open(pid)
    run = _Run(pid, conn, pidfd)
    srv.runs[pid] = run
    srv.sel.register(pidfd, selectors.EVENT_READ, ("end", run))
    srv.sel.register(conn, selectors.EVENT_READ, ("client", run))
    os.close(go_r)
    try:
        conn.send(json.dumps({"pid": pid}).encode())
        os.write(go_w, b"1")
    except OSError:
        os.write(go_w, b"0")
    os.close(go_w)
    return None


def _close(fds: list[int]) -> None:
    for fd in fds:
        try:
            os.close(fd)
        except OSError:
            pass


def _ended(srv: _Server, run: _Run) -> None:
    """Reap ``run`` and tell its client how it ended."""
    _, status = os.waitpid(run.pid, 0)
    end = {"signal": os.WTERMSIG(status)} if os.WIFSIGNALED(status) else {"exit": os.waitstatus_to_exitcode(status)}
    try:
        run.conn.send(json.dumps(end).encode())
    except OSError:
        pass
    srv.sel.unregister(run.pidfd)
    srv.sel.unregister(run.conn)
    os.close(run.pidfd)
    run.conn.close()
    del srv.runs[run.pid]


def _client_event(run: _Run) -> None:
    """The client's end of ``run`` is readable: it went away (its data is never more than EOF) → stop the run."""
    try:
        gone = run.conn.recv(16, socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return
    except OSError:
        gone = True
    if gone:
        try:
            os.kill(run.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass


def serve(path: str, parent: int | None = None, path_at_start: list[str] | None = None,
          env_at_start: dict[str, str] | None = None) -> dict | None:
    """Listen on ``path`` and fork a child per request until SIGTERM/SIGINT, or until ``parent`` (a pid) is gone.
    Returns None in the server when it stops (after its runs ended, or :data:`STOP_GRACE_S`), the request in each
    forked child, or ``{"restart": True}`` when framework code changed and no run is left. ``path_at_start``: the
    import path before :func:`preload` (a client's must equal it but for its first entry); ``env_at_start``: the
    environment before it (a client's must equal it in :data:`IMPORT_TIME_ENV`; what the imports changed in it is
    changed in each child's environment too, as the same imports would in a fresh process)."""
    env0 = dict(os.environ if env_at_start is None else env_at_start)
    delta = {k: v for k, v in os.environ.items() if env0.get(k) != v} | {k: None for k in env0 if k not in os.environ}
    srv = _Server(path, _listen(path), selectors.DefaultSelector(), env0, delta, code_fingerprint(),
                  list(sys.path if path_at_start is None else path_at_start))
    srv.sel.register(srv.listener, selectors.EVENT_READ, ("listen", None))
    stop = srv.stopping
    signal.signal(signal.SIGTERM, lambda s, _f: stop.append(s))
    signal.signal(signal.SIGINT, lambda s, _f: stop.append(s))
    print(f"aerodaas warm driver: listening on {path} (pid {os.getpid()})", flush=True)
    deadline = None
    while True:
        if (stop or (parent and os.getppid() != parent)) and deadline is None:
            deadline = time.monotonic() + STOP_GRACE_S
            srv.sel.unregister(srv.listener)
            srv.listener.close()
            _unlink(path)
            for pid in srv.runs:
                os.kill(pid, signal.SIGTERM)
        if deadline is not None and (not srv.runs or time.monotonic() > deadline):
            return None
        if srv.stale and not srv.runs:
            srv.listener.close()
            _unlink(path)
            return {"restart": True}
        for key, _ in srv.sel.select(timeout=1.0):
            kind, run = key.data
            if kind == "listen":
                req = _accept(srv)
                if req is not None:
                    return req
            elif kind == "end":
                _ended(srv, run)
            elif run.pid in srv.runs:
                _client_event(run)


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def main(argv: list[str]) -> int:
    """``python -P -m aerodaas.clusters.warm_driver SOCKET [PARENT_PID]``: preload, serve; in a forked child run
    the command line. Exit 3 when a preload import would make forking unsafe (the reason printed)."""
    path, parent = argv[0], int(argv[1]) if len(argv) > 1 else None
    path_at_start, env_at_start = list(sys.path), dict(os.environ)
    try:
        preload()
    except ForkSafetyError as e:
        print(f"aerodaas warm driver: not started: {e}", flush=True)
        return 3
    req = serve(path, parent, path_at_start, env_at_start)
    if req is None:
        return 0
    if req.get("restart"):
        print("aerodaas warm driver: framework code edited: starting afresh", flush=True)
        os.execv(sys.executable, [sys.executable, "-P", "-m", "aerodaas.clusters.warm_driver", *argv])
    return importlib.import_module(COMMAND_LINE).main(sys.argv[1:], own_process=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
