"""``aerodaas replay``: serve a recording to Foxglove over WebSocket."""
from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

def run(args: argparse.Namespace) -> int:
    """``aerodaas replay FILE.mcap --live [HOST:PORT] [--speed K]``: serve a recording to Foxglove over WebSocket
    (:func:`aerodaas.liveview.server.replay`). Exit 0 when played to the end or stopped (Ctrl-C, SIGTERM), 2 for a bad file,
    address or speed."""
    from aerodaas.liveview.server import (  # lazy: CLI start-up (OpenCV and MCAP)
        check_bindable, live_access, parse_address, replay, write_live_state)

    try:
        host, port = parse_address(args.live)
        check_bindable(host, port)
        access = live_access(host, args.tls_cert, args.tls_key, bool(args.insecure))
        if not args.speed > 0:
            raise ValueError(f"--speed must be a positive number (1 = as recorded), got {args.speed!r}")
        if not Path(args.file).is_file():
            raise FileNotFoundError(f"recording {args.file!r} not found")
    except (ValueError, FileNotFoundError) as e:
        print(f"aerodaas replay: {e}", file=sys.stderr)
        return 2

    def on_sigterm(signum, frame):  # the same clean stop as Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt(f"signal {signum}")

    def ready(server) -> None:
        wait = "" if args.no_wait else "; playback starts when a client subscribes"
        token = f"; token in {write_live_state(server.url, access)}, owner only" if access.token else ""
        print(f"aerodaas replay: serving {args.file} at {server.url} ({args.speed:g}x){wait}{token}", flush=True)
        if access.insecure:
            print(f"aerodaas replay: WARNING: serving plain WebSocket off loopback ({server.url}, --insecure): the "
                  f"recording can be read on the network", file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        out = replay(args.file, args.live, speed=args.speed, on_ready=ready, access=access,
                     wait_for_client_s=None if args.no_wait else float("inf"))
    except KeyboardInterrupt:
        print("aerodaas replay: stopped", file=sys.stderr, flush=True)
        return 0
    except (OSError, ValueError, RuntimeError) as e:
        print(f"aerodaas replay: {e}", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, previous)
    insecure = "; INSECURE: served in clear text off loopback (--insecure)" if access.insecure else ""
    print(f"aerodaas replay: {out['messages']} messages, {out['duration_s']:.1f} s of recording in "
          f"{out['wall_s']:.1f} s{insecure}", flush=True)
    return 0


def add_parser(sub) -> None:
    """``aerodaas replay FILE --live [HOST:PORT] [--speed K] [--no-wait]``."""
    rp = sub.add_parser("replay", help="serve an MCAP recording to Foxglove over WebSocket, at 1x or faster")
    rp.add_argument("file")
    rp.add_argument("--live", nargs="?", const="", required=True, metavar="HOST:PORT",
                    help="address to serve on (default 127.0.0.1:8765; port 0: any free port)")
    rp.add_argument("--speed", type=float, default=1.0, help="playback speed over the recorded time (default 1)")
    rp.add_argument("--no-wait", action="store_true", help="start at once instead of when a client subscribes")
    rp.add_argument("--tls-cert", metavar="PEM", help="certificate (chain): serve WSS (needed off loopback)")
    rp.add_argument("--tls-key", metavar="PEM", help="private key of --tls-cert (mode 0600)")
    rp.add_argument("--insecure", action="store_true", help="serve plain WebSocket off loopback (no certificate)")
    rp.set_defaults(func=run)
