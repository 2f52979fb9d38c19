"""Command-line and application cases of ``python -m aerodaas.reliability``: ``aerodaas run`` flags that must be
refused before Ray starts (exit 2, naming the flag), and applications whose own code raises (exit 1, the app's
traceback, never "bad input"). Each case runs :func:`aerodaas.cli.main` in this process with Ray's start replaced
by a guard that records any attempt (a case that reaches Ray fails)."""
from __future__ import annotations

import contextlib
import io
import json
import socket
import tempfile
from pathlib import Path
from typing import Any, Callable, NamedTuple

from aerodaas import cli
from aerodaas.runtime import ray_start

__all__ = ["CLI_CASES", "HeldArgv", "run_cli_cases"]

_APP = """
from aerodaas import *
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
drone.start_mission()
"""


def base_env() -> dict:
    """A valid environment: one simulated drone with a camera and odometry."""
    return {"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera"}, {"id": "odom", "type": "odometry"}]}]}


def _app(tmp: Path, text: str | None = None, env: dict | None = None) -> str:
    e = tmp / "cli_env.json"
    e.write_text(json.dumps(env or {"robots": [{"id": "d1"}]}))
    a = tmp / "cli_app.py"
    a.write_text(text if text is not None else _APP.format(env=str(e)))
    return str(a)


class HeldArgv(NamedTuple):
    """What a case's builder returns when something must stay open while the case runs: the ``argv`` and the
    sockets ``held`` (:func:`run_cli_cases` closes them after the case)."""

    argv: list[str]
    held: tuple[socket.socket, ...]


def _busy_hitl(tmp: Path) -> HeldArgv:
    """A HITL port that is already in use: a socket listening on it, held for the case."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    return HeldArgv([_app(tmp, env={"robots": [{"id": "d1"}], "hitl": {"enabled": True,
                                                                        "port": s.getsockname()[1]}})], (s,))

#: (name, argv after ``run`` (made in a scratch folder), expected exit code, text the message must contain)
CLI_CASES: list[tuple[str, Callable[[Path], list[str] | HeldArgv], int, str]] = [
    ("--env ''", lambda t: [_app(t), "--env", ""], 2, "--env"),
    ("--env '   '", lambda t: [_app(t), "--env", "   "], 2, "--env"),
    ("--record ''", lambda t: [_app(t), "--record", ""], 2, "--record"),
    ("--address not-a-host:1", lambda t: [_app(t), "--address", "not-a-host:1"], 2, "not-a-host"),
    ("--address 127.0.0.1:1 (nothing listening)", lambda t: [_app(t), "--address", "127.0.0.1:1"], 2, "127.0.0.1:1"),
    ("--address 127.0.0.1:70000", lambda t: [_app(t), "--address", "127.0.0.1:70000"], 2, "70000"),
    ("--address without a port", lambda t: [_app(t), "--address", "headnode"], 2, "HOST:PORT"),
    ("--hitl-port 70000", lambda t: [_app(t), "--hitl-port", "70000"], 2, "--hitl-port"),
    ("--hitl-port -1", lambda t: [_app(t), "--hitl-port", "-1"], 2, "--hitl-port"),
    ("hitl.port in use", _busy_hitl, 2, "cannot listen"),
    ("hitl.host 192.0.2.1 (not this machine)",
     lambda t: [_app(t, env={"robots": [{"id": "d1"}], "hitl": {"enabled": True, "host": "192.0.2.1"}})], 2,
     "cannot listen"),
    ("the app's own KeyError", lambda t: [_app(t, "cfg = {}\ncfg['missing']\n")], 1, "the application"),
    ("the app's own RuntimeError", lambda t: [_app(t, "raise RuntimeError('app bug')\n")], 1, "the application"),
    ("the app's json.loads of bad text", lambda t: [_app(t, "import json\njson.loads('{x')\n")], 1,
     "the application"),
    ("an environment file that does not exist (AeroDaaS refuses it)",
     lambda t: [_app(t, _APP.format(env=str(t / "none.json")))], 2, "none.json"),
]


def run_cli_cases(cases: list | None = None, category: str | None = None) -> list[dict[str, Any]]:
    """Run ``cases`` (default :data:`CLI_CASES`; each builder returns the ARGV, or a :class:`HeldArgv`) as
    ``aerodaas run ARGV --quiet``; rows ``{"kind", "category",
    "name", "refused", "message", "traceback"}`` (``refused``: the expected exit code, the expected text, Ray never
    started, and a traceback exactly for the app's own errors; ``traceback``: one printed where none belongs).
    ``category``: the rows' report group (default: "command line" for exit 2, "app-level errors" for exit 1)."""
    rows = []
    saved = (ray_start.init_ray, ray_start.start_ray_early, ray_start.shutdown_ray)
    started: list = []
    ray_start.init_ray = lambda address, dashboard=False: started.append(address)
    ray_start.start_ray_early = lambda address=None, dashboard=False: started.append(("early", address))
    ray_start.shutdown_ray = lambda: None
    try:
        for name, make, code, expect in (CLI_CASES if cases is None else cases):
            with tempfile.TemporaryDirectory() as td:
                started.clear()
                err = io.StringIO()
                made = make(Path(td))
                args, held = (made.argv, made.held) if isinstance(made, HeldArgv) else (made, ())
                try:
                    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                        got = cli.main(["run", *args, "--quiet"])
                finally:
                    for s in held:
                        s.close()
                msg = err.getvalue().strip()
                tb_ok = ("Traceback" in msg) == (code == 1)
                ok = got == code and expect in msg and not started and tb_ok
                rows.append({"kind": "command line" if code == 2 else "application error", "name": name,
                             "category": category or ("command line" if code == 2 else "app-level errors"),
                             "refused": ok, "message": f"exit {got}: {msg}" if msg else f"exit {got}",
                             "traceback": "Traceback" in msg and code != 1})
    finally:
        ray_start.init_ray, ray_start.start_ray_early, ray_start.shutdown_ray = saved
    return rows
