"""``aerodaas sim``: the flight model served as a MAVLink vehicle."""
from __future__ import annotations

import argparse
import signal
import sys
import time

def run(args: argparse.Namespace) -> int:
    """``aerodaas sim --mavlink ADDR``: the flight model as an ArduPilot/PX4 vehicle until Ctrl-C or SIGTERM
    (``kill``, ``docker stop``, systemd), either of which stops it cleanly: sockets closed, exit code 0 (stopping
    is how a server ends, unlike ``run``'s interrupted mission); 2 for a bad argument or address."""
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator  # lazy: CLI start-up (pydantic and pymavlink)
    from aerodaas.model.types import GeoPoint  # lazy: CLI start-up (pydantic)

    home = None
    if args.home:
        try:
            lat, lon, alt = (float(v) for v in args.home.split(","))
            home = GeoPoint(lat=lat, lon=lon, alt=alt)
        except ValueError as e:
            print(f"aerodaas sim: --home expects LAT,LON,ALT (degrees, degrees, metres AMSL), got {args.home!r} "
                  f"({e})", file=sys.stderr)
            return 2
    try:
        emu = MavlinkVehicleEmulator(args.autopilot, home=home, speedup=args.speedup, system_id=args.sysid)
        address = emu.start(args.mavlink, allow_remote=args.allow_remote)
    except (ValueError, OSError) as e:
        print(f"aerodaas sim: {e}", file=sys.stderr)
        return 2

    def on_sigterm(signum, frame):  # the same clean stop as Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # one clean stop; a second SIGTERM must not cut it short
        raise KeyboardInterrupt(f"signal {signum}")

    previous_sigterm = None
    try:
        try:
            previous_sigterm = signal.signal(signal.SIGTERM, on_sigterm)
        except ValueError:  # not the main thread (main() called from a worker thread): Ctrl-C only
            pass
        print(f"aerodaas sim: {args.autopilot} vehicle (system {args.sysid}) on {address}, {args.speedup:g}x real "
              "time; Ctrl-C or SIGTERM to stop", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("aerodaas sim: stopped", file=sys.stderr, flush=True)
        return 0
    finally:
        if previous_sigterm is not None:  # no signal may cut the clean stop short
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        emu.stop()
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)


def add_parser(sub) -> None:
    """``aerodaas sim --mavlink ADDR [--autopilot ardupilot|px4] ...``."""
    sm = sub.add_parser("sim", help="serve the simulator as a MAVLink vehicle (ArduPilot or PX4 behaviour)")
    sm.add_argument("--mavlink", required=True, metavar="ADDR",
                    help="tcp:HOST:PORT (server), udpin:HOST:PORT or udpout:HOST:PORT, e.g. tcp:127.0.0.1:5760")
    sm.add_argument("--autopilot", choices=["ardupilot", "px4"], default="ardupilot")
    sm.add_argument("--speedup", type=float, default=1.0, help="vehicle time runs K times faster than real time")
    sm.add_argument("--home", metavar="LAT,LON,ALT", help="home position (degrees, degrees, metres AMSL)")
    sm.add_argument("--sysid", type=int, default=1, help="MAVLink system id (default 1)")
    sm.add_argument("--allow-remote", action="store_true", help="allow a non-loopback address")
    sm.set_defaults(func=run)
