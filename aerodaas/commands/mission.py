"""``aerodaas mission upload FILE`` / ``aerodaas mission download --out FILE``: QGroundControl ``.plan`` and
``QGC WPL 110`` missions to and from a MAVLink vehicle, with no Ray and no environment file: the options (this
module, parsed at every ``aerodaas`` start) and its handlers :func:`run_upload` and :func:`run_download` (the work:
:mod:`aerodaas.tools.mission_transfer`)."""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_parser", "run_download", "run_upload"]


def _upload_bound(kind: str):
    """argparse type of a positive bound: an ``altitude`` at most ``MAX_ALTITUDE_M`` (10 km), a ``distance`` at most
    ``MAX_LOCAL_M`` (100 km), a ``speed`` at most ``MAX_SPEED_MPS`` m/s; argparse names the option in its error
    (exit 2)."""

    def parse(text: str) -> float:
        from aerodaas.model.bounds import MAX_ALTITUDE_M, MAX_SPEED_MPS  # lazy: CLI start-up (pydantic)
        from aerodaas.model.types import MAX_LOCAL_M  # lazy: CLI start-up (pydantic)

        upper = {"altitude": MAX_ALTITUDE_M, "distance": MAX_LOCAL_M, "speed": MAX_SPEED_MPS}[kind]
        unit = "m/s" if kind == "speed" else "metres"
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not 0.0 < v <= upper:
            raise argparse.ArgumentTypeError(f"must be in (0, {upper:g}] {unit}, got {text}")
        return v

    return parse


def run_upload(args: argparse.Namespace) -> int:
    """``aerodaas mission upload FILE``: :func:`aerodaas.tools.mission_transfer.upload` (exit 0, 2 for a file,
    bound or vehicle that refuses the mission, named)."""
    from aerodaas.tools.mission_transfer import Upload, upload  # lazy: CLI start-up (pydantic, pymavlink)

    return upload(Upload(file=Path(args.file), link=_link(args), start=args.start, fence_action=args.fence_action,
                         max_altitude_m=args.max_altitude, max_distance_m=args.max_distance,
                         max_speed_mps=args.max_speed))


def run_download(args: argparse.Namespace) -> int:
    """``aerodaas mission download --out FILE``: :func:`aerodaas.tools.mission_transfer.download` (exit 0, 2 for a
    file or vehicle that refuses, named)."""
    from aerodaas.tools.mission_transfer import Download, download  # lazy: CLI start-up (pydantic, pymavlink)

    return download(Download(out=Path(args.out), link=_link(args)))


def _link(args: argparse.Namespace):
    """The :class:`~aerodaas.tools.mission_transfer.VehicleLink` of ``--connection``, ``--autopilot``, ``--timeout``
    and ``--key-file``."""
    from aerodaas.tools.mission_transfer import VehicleLink  # lazy: CLI start-up (pydantic, pymavlink)

    return VehicleLink(connection=args.connection, autopilot=args.autopilot, timeout_s=args.timeout,
                       key_file=args.key_file)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``mission upload`` / ``mission download`` on the CLI's sub-parsers."""
    ms = sub.add_parser("mission", help="upload a .plan / QGC WPL mission to a MAVLink vehicle, or download one")
    msub = ms.add_subparsers(dest="mission_cmd", required=True)
    mu = msub.add_parser("upload", help="check FILE (.plan, .waypoints, .txt) and upload it (MISSION_ITEM_INT)")
    mu.add_argument("file")
    mu.add_argument("--start", action="store_true", help="then arm and start it (ArduPilot AUTO / PX4 AUTO.MISSION)")
    mu.add_argument("--fence-action", choices=["rtl", "land", "hold", "report"], default="rtl",
                    help="the vehicle's own action when it breaches the plan's geofence (ArduPilot FENCE_ACTION, PX4 "
                         "GF_ACTION; default rtl)")
    mu.add_argument("--max-altitude", type=_upload_bound("altitude"), default=120.0, metavar="M",
                    help="refuse items higher than this above home, metres (default 120: the EU open category "
                         "and FAA Part 107 ceiling)")
    mu.add_argument("--max-distance", type=_upload_bound("distance"), default=10_000.0, metavar="M",
                    help="refuse items farther than this from home horizontally, metres (default 10000)")
    mu.add_argument("--max-speed", type=_upload_bound("speed"), default=None, metavar="M/S",
                    help="cap the file's speeds (DO_CHANGE_SPEED items) at this, m/s, and start the flight at it when "
                         "the vehicle's own cruise speed is higher; each item changed is printed (default: the "
                         "file's speeds as written)")
    md = msub.add_parser("download", help="download the vehicle's mission into --out (.plan, .waypoints or .txt)")
    md.add_argument("--out", required=True, metavar="FILE")
    for m in (mu, md):
        m.add_argument("--connection", required=True, metavar="CONN",
                       help="pymavlink connection string, e.g. tcp:127.0.0.1:5760, udpin:0.0.0.0:14550, /dev/ttyACM0")
        m.add_argument("--autopilot", choices=["auto", "ardupilot", "px4"], default="auto")
        m.add_argument("--timeout", type=float, default=10.0, help="seconds to reach the vehicle (default 10)")
        m.add_argument("--key-file", metavar="F", default=None,
                       help="MAVLink 2 signing key file of the vehicle (32 bytes, 64 hex characters, mode 0600; "
                            "docs/security.md): everything sent is signed, only correctly signed messages are taken")
    mu.set_defaults(func=run_upload)
    md.set_defaults(func=run_download)
