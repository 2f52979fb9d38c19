"""``aerodaas run APP.py``: its options, parsed at every ``aerodaas`` start (this module imports nothing heavy), and
its handler :func:`cmd_run`, which marks the CLI's start (``aerodaas bench startup``) and runs the command
(:func:`aerodaas.commands.run_main.run`: Ray, the runtime and the configuration are imported from there)."""
from __future__ import annotations

import argparse

from aerodaas.protocol.startup_probe import probe


def add_parser(sub) -> None:
    """Register the ``run`` sub-command on the CLI's sub-parsers ``sub``."""
    r = sub.add_parser("run", help="run an application (APP.py) on the embedded simulator or real drones")
    r.add_argument("app")
    r.add_argument("--env", help="environment.json to use instead of the one the app names")
    r.add_argument("--record", help="write the run to this MCAP file")
    r.add_argument("--speedup", type=float, help="simulation speed-up over real time (default: from the env file)")
    r.add_argument("--lockstep", action="store_true", help="simulated time waits for analytics on every frame")
    r.add_argument("--recorder-hold", type=float, metavar="S", help="wall seconds in all a simulated run's clock may "
                   "wait for a recorder that falls behind instead of dropping frames (0 to 3600; over "
                   "simulation.recorder_hold_s, default 120)")
    r.add_argument("--timeout", type=float, help="wall-clock limit in seconds")
    r.add_argument("--overwrite", action="store_true", help="let --record replace an existing file that is not an "
                   "AeroDaaS recording (the app and its environment file are never replaced)")
    r.add_argument("--address", help="attach to an existing Ray cluster (e.g. 'auto') instead of starting one")
    r.add_argument("--quiet", action="store_true", help="no live progress")
    r.add_argument("--dashboard", action="store_true",
                   help="start Ray's dashboard with the local Ray (127.0.0.1:8265): `ray list actors`, the actors view")
    r.add_argument("--hitl", action="store_true", help="serve the human-in-the-loop API (its token in the owner-only "
                   "state file $AERODAAS_STATE_DIR/hitl.json)")
    r.add_argument("--hitl-port", type=int, help="port of the human-in-the-loop API (0: any free port)")
    r.add_argument("--live", nargs="?", const="", metavar="HOST:PORT",
                   help="serve the run to Foxglove over WebSocket (default 127.0.0.1:8765; port 0: any free port; "
                   "off loopback: WSS and a token, see --tls-cert)")
    r.add_argument("--tls-cert", metavar="PEM", help="certificate (chain) of the HITL API and the live view: they "
                   "serve HTTPS/WSS (needed to bind off loopback; over hitl.tls_cert)")
    r.add_argument("--tls-key", metavar="PEM", help="private key of --tls-cert (mode 0600)")
    r.add_argument("--insecure", action="store_true", help="let the HITL API and the live view serve in clear text "
                   "off loopback without a certificate (the summary says so)")
    r.set_defaults(func=cmd_run)


def cmd_run(args: argparse.Namespace) -> int:
    """``aerodaas run APP.py``: load the application and fly it (:func:`aerodaas.commands.run_main.run`); the exit
    code of its missions' results (see the README), 2 for bad input named before Ray starts."""
    probe("cli")
    from aerodaas.commands.run_main import run  # lazy: CLI start-up (Ray, pydantic, the runtime)

    return run(args)
