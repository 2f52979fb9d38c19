"""The client side of the warm driver (:mod:`aerodaas.clusters.warm_driver`): whether ``aerodaas run`` hands its
command to the pre-imported driver process of ``aerodaas up``, and the hand-over itself.

This module is imported by every ``aerodaas`` start before anything else of the framework runs, so it imports only
the standard library, and only what the decision needs (``socket`` and ``json`` once a server socket exists).

The hand-over, over a ``SOCK_SEQPACKET`` Unix socket (one message each way, boundaries kept): the client sends one
JSON request (its ``sys.argv``, working folder, environment, ``sys.path``, interpreter, the encoding and buffering of
its standard streams, umask, niceness, CPU affinity, resource limits and the signals it ignores) with its file
descriptors 0, 1 and 2 attached (``SCM_RIGHTS``: :func:`socket.send_fds`); the server answers ``{"pid": N}`` (the
forked run) or ``{"refused": why}`` (the client then runs the command itself), and, when the run ends,
``{"exit": code}`` or ``{"signal": n}``. Meanwhile the client forwards SIGINT (to the run's process group, as a
terminal's Ctrl-C reaches a foreground group), SIGTERM, SIGHUP, SIGQUIT and SIGWINCH to the run.
"""
from __future__ import annotations

import os
import signal
import sys

from aerodaas.clusters.state_folder import state_dir

__all__ = ["NO_WARM_DRIVER_ENV", "delegate", "socket_path"]

#: ``AERODAAS_NO_WARM_DRIVER=1``: ``aerodaas run`` never uses the warm driver
NO_WARM_DRIVER_ENV = "AERODAAS_NO_WARM_DRIVER"

#: the signals the client passes on to the run while it waits
FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGWINCH)

#: the resource limits the run gets from the client (``resource.RLIMIT_*`` names)
RLIMITS = ("RLIMIT_NOFILE", "RLIMIT_CORE", "RLIMIT_AS", "RLIMIT_DATA", "RLIMIT_STACK", "RLIMIT_FSIZE",
           "RLIMIT_NPROC", "RLIMIT_MEMLOCK")

#: how long the client waits for the server's answer to its request; without one it runs the command itself (the
#: server lets a run start only once that answer is sent, so a client that gave up earlier never runs it twice)
ANSWER_TIMEOUT_S = 60.0

#: longest path a Unix socket address holds on Linux (``sun_path``: 108 bytes with its terminating NUL)
_MAX_SOCKET_PATH = 107


def socket_path(environ: dict[str, str] | None = None) -> str:
    """Where the warm driver of the ``aerodaas up`` cluster listens: ``run/warm-driver.sock`` in its state folder
    (:func:`aerodaas.clusters.state_folder.state_dir`), or, when
    that path is longer than a Unix socket address holds (107 bytes), ``/tmp/aerodaas-<uid>/<digest>.sock`` with
    the digest of the state folder's real path. The folder is the server's to create (mode 0700)."""
    base = state_dir(environ)
    path = os.path.join(base, "run", "warm-driver.sock")
    if len(os.fsencode(path)) <= _MAX_SOCKET_PATH:
        return path
    import hashlib  # lazy: long state folders only

    digest = hashlib.blake2b(os.fsencode(os.path.realpath(base)), digest_size=10).hexdigest()
    return os.path.join("/tmp", f"aerodaas-{os.getuid()}", f"{digest}.sock")


def _wanted(argv: list[str]) -> bool:
    """Whether ``argv`` (``sys.argv``) is an ``aerodaas run`` that attaches to the cluster of ``aerodaas up``: not
    ``--address`` (or an abbreviation argparse accepts), not ``AERODAAS_NO_ATTACH=1``, not
    ``AERODAAS_NO_WARM_DRIVER=1``."""
    if argv[1:2] != ["run"] or os.environ.get(NO_WARM_DRIVER_ENV) == "1" or os.environ.get("AERODAAS_NO_ATTACH") == "1":
        return False
    return not any(a.startswith("--ad") for a in argv[2:])


def _stream(f) -> list | None:
    """How the interpreter set up the standard stream ``f``: ``[encoding, errors, line_buffering, write_through]``
    (None: the stream is missing)."""
    if f is None:
        return None
    return [f.encoding, f.errors, bool(getattr(f, "line_buffering", False)), bool(getattr(f, "write_through", False))]


def _request(argv: list[str]) -> dict | None:
    """The request for the server, or None when this process cannot hand its streams over (a closed 0, 1 or 2)."""
    import resource  # lazy: a hand-over only

    streams = [_stream(sys.stdin), _stream(sys.stdout), _stream(sys.stderr)]
    if None in streams:
        return None
    try:
        for fd in (0, 1, 2):
            os.fstat(fd)
    except OSError:
        return None
    mask = os.umask(0)
    os.umask(mask)
    return {"argv": list(argv), "cwd": os.getcwd(), "env": dict(os.environ), "path": list(sys.path),
            "exe": sys.executable, "streams": streams, "umask": mask, "nice": os.getpriority(os.PRIO_PROCESS, 0),
            "affinity": sorted(os.sched_getaffinity(0)), "client": os.getpid(),
            "rlimits": {n: list(resource.getrlimit(getattr(resource, n))) for n in RLIMITS if hasattr(resource, n)},
            "ignored": [int(s) for s in FORWARDED if signal.getsignal(s) == signal.SIG_IGN]}


def delegate(argv: list[str] | None = None) -> int | None:
    """Run ``argv`` (default ``sys.argv``) in the warm driver when it is an attached ``aerodaas run`` and the
    server of ``aerodaas up`` answers; returns the run's exit code, or None when this process must run the command
    itself (no server, a stale socket file, the server refused, ``AERODAAS_NO_WARM_DRIVER=1``). A run killed by a
    signal kills this process with the same signal. Never raises for a missing or broken server."""
    argv = list(sys.argv if argv is None else argv)
    if not _wanted(argv):
        return None
    path = socket_path()
    if not os.path.exists(path):
        return None
    import json  # lazy: a server socket exists
    import socket  # lazy: a server socket exists

    req = _request(argv)
    if req is None:
        return None
    fwd = _Forwarder(set(req["ignored"]))
    sock = None
    try:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        sock.settimeout(5.0)
        sock.connect(path)
        socket.send_fds(sock, [json.dumps(req).encode()], [0, 1, 2])
        sock.settimeout(ANSWER_TIMEOUT_S)
        first = json.loads(sock.recv(65536) or b"{}")
    except (OSError, ValueError):
        first = {}  # stale socket file, a server that went away, a request too large: run it here
    if "pid" not in first:
        if sock is not None:
            sock.close()
        fwd.give_back()
        return None
    fwd.to(int(first["pid"]))
    sock.settimeout(None)
    try:
        end = json.loads(sock.recv(65536) or b"{}")
    except (OSError, ValueError):
        end = {}
    finally:
        sock.close()
    return _exit(end, int(first["pid"]))


class _Forwarder:
    """The client's handler of :data:`FORWARDED` (but those it ignores): until the run's pid is known the signals
    wait; then each goes to the run (SIGINT to its process group). :meth:`give_back` restores the handlers and
    delivers what waited to this process (the client then runs the command itself)."""

    def __init__(self, ignored: set[int]) -> None:
        self.pid: int | None = None
        self.pending: list[int] = []
        self.previous = {s: signal.signal(s, self) for s in FORWARDED if int(s) not in ignored}

    def __call__(self, signum, _frame) -> None:
        if self.pid is None:
            self.pending.append(signum)
            return
        try:
            if signum == signal.SIGINT:
                os.killpg(self.pid, signum)
            else:
                os.kill(self.pid, signum)
        except OSError:
            pass

    def to(self, pid: int) -> None:
        self.pid = pid
        for signum in self.pending:
            self(signum, None)

    def give_back(self) -> None:
        for s, h in self.previous.items():
            signal.signal(s, h)
        for signum in self.pending:
            os.kill(os.getpid(), signum)


def _exit(end: dict, pid: int) -> int:
    """The exit code for the server's report ``end`` of the run ``pid``: a run killed by a signal kills this
    process with the same signal."""
    if "signal" in end:
        n = int(end["signal"])
        signal.signal(n, signal.SIG_DFL)
        os.kill(os.getpid(), n)
        return 128 + n
    if "exit" in end:
        return int(end["exit"])
    print(f"aerodaas run: the warm driver of `aerodaas up` stopped before the run (pid {pid}) ended",
          file=sys.stderr, flush=True)
    return 1
