"""``aerodaas run APP.py``: its options, parsed at every ``aerodaas`` start (this module imports nothing heavy), and
its handler :func:`run`, which marks the CLI's start (``aerodaas bench startup``), checks the flags into the run's
options before Ray starts and flies the application (:func:`aerodaas.runtime.fly.fly`: Ray, the runtime and the
configuration are imported from there)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

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
    r.set_defaults(func=run)


def _run_options(args: argparse.Namespace):
    """``aerodaas run``'s flags as the run's :class:`~aerodaas.runtime.options.RunOptions`, every one checked before
    Ray starts (exit 2 naming the bad input: the returned int)."""
    from aerodaas.config import ConfigError  # lazy: CLI start-up (pydantic)
    from aerodaas.runtime.options import RunOptions  # lazy: CLI start-up (the runtime)
    from aerodaas.runtime.preflight import check_run_flags  # lazy: CLI start-up (pydantic, the runtime)

    try:
        check_run_flags(args.record, args.env, args.speedup, args.timeout, args.hitl_port, args.address,
                        app=str(args.app), overwrite=args.overwrite)
    except (ConfigError, ValueError) as e:
        print(f"aerodaas run: {e}", file=sys.stderr)
        return 2
    live = access = None
    if args.live is not None:
        from aerodaas.liveview.server import check_bindable, live_access, parse_address  # lazy: --live only (cv2)

        try:
            host, port = parse_address(args.live)
            if not args.address:  # local run: the edge host (which serves) is on this machine
                check_bindable(host, port)
            access = live_access(host, args.tls_cert, args.tls_key, bool(args.insecure))
        except ValueError as e:
            print(f"aerodaas run: {e}", file=sys.stderr)
            return 2
        live = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    return RunOptions(record=args.record, speedup=args.speedup, timeout=args.timeout, address=args.address,
                      overwrite=bool(args.overwrite), env_path=str(Path(args.env).resolve()) if args.env else None,
                      lockstep=True if args.lockstep else None, recorder_hold_s=args.recorder_hold, dashboard=bool(getattr(args, "dashboard", False)),
                      progress=not args.quiet, hitl=True if args.hitl else None, hitl_port=args.hitl_port, live=live,
                      live_access=access, tls_cert=args.tls_cert, tls_key=args.tls_key, insecure=bool(args.insecure))


def run(args: argparse.Namespace) -> int:
    """``aerodaas run APP.py``: mark the CLI's start, check the flags (exit 2 naming bad input before any Ray
    process exists), then load the application and fly it with the built-in actors
    (:func:`aerodaas.runtime.fly.fly`); the exit code of its missions' results (see the README)."""
    probe("cli")
    app = Path(args.app)
    if not app.is_file():
        print(f"aerodaas run: application file {str(app)!r} not found", file=sys.stderr)
        return 2
    opts = _run_options(args)
    if isinstance(opts, int):
        return opts
    from aerodaas.app.api import with_builtin_actors  # lazy: CLI start-up (pydantic, the application API)
    from aerodaas.runtime.fly import fly  # lazy: CLI start-up (the runtime)

    # the run's actors are handed to the runtime (which imports none): the built-in ones
    return fly(app, with_builtin_actors(opts), own_process=getattr(args, "own_process", False))
