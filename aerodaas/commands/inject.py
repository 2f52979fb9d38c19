"""``aerodaas inject``: waypoints into a running mission through the human-in-the-loop API."""
from __future__ import annotations

import argparse
import json
import sys

def parse_waypoint(text: str) -> dict:
    """``x,y,z[,hover]`` (ENU metres from home, hover seconds) -> a waypoint request dict."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError(f"--waypoint expects x,y,z[,hover] (metres, seconds), got {text!r}")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--waypoint expects numbers x,y,z[,hover], got {text!r}") from None
    wp = {"x": vals[0], "y": vals[1], "z": vals[2]}
    if len(vals) == 4:
        wp["hover_duration"] = vals[3]
    return wp


def run(args: argparse.Namespace) -> int:
    """``aerodaas inject``: POST the waypoints to the running mission's human-in-the-loop API
    (:func:`aerodaas.tools.hitl_client.request`). Exit 0, 1 when the API refuses them (its HTTP status and reason),
    2 when it cannot be reached, no token is known, or the URL is refused before any connection (the state file's
    token asked for another server, plain http off loopback without ``--insecure-http``: the module docstring of
    :mod:`aerodaas.tools.hitl_client`)."""
    from aerodaas.tools import hitl_client  # lazy: CLI start-up

    if args.insecure_http:
        print("aerodaas inject: WARNING: --insecure-http: a plain http URL off loopback gets the bearer token in "
              "clear text; anyone on the network path can read it and steer the vehicles", file=sys.stderr)

    body: dict = {"waypoints": args.waypoint, "scheduling_type": "ORDERED" if args.ordered else "UNORDERED"}
    if args.index is not None:
        body["index"] = args.index
    if args.priority is not None:
        body["priority"] = args.priority
    try:
        status, out = hitl_client.request("POST", f"/drones/{args.drone}/waypoints", body, url=args.url,
                                          token=args.token, cafile=args.cacert, insecure_http=args.insecure_http)
    except (RuntimeError, ValueError) as e:
        print(f"aerodaas inject: {e}", file=sys.stderr)
        return 2
    if status != 200:
        detail = out.get("detail") if isinstance(out, dict) else out
        if isinstance(detail, list):
            detail = "; ".join(f"{'.'.join(str(x) for x in d.get('loc', []))}: {d.get('msg')}" for d in detail)
        print(f"aerodaas inject: HTTP {status}: {detail}", file=sys.stderr)
        return 1
    print(json.dumps(out, indent=2) if args.json else f"queued {', '.join(out['added'])} for {args.drone}")
    return 0


def add_parser(sub) -> None:
    """``aerodaas inject --drone ID --waypoint x,y,z[,hover] ...``."""
    j = sub.add_parser("inject", help="add waypoints to a running mission through the human-in-the-loop API")
    j.add_argument("--drone", required=True, help="robot id")
    j.add_argument("--waypoint", required=True, action="append", type=parse_waypoint,
                   help="x,y,z[,hover]: ENU metres from home and hover seconds (repeatable)")
    j.add_argument("--index", type=int, help="insert at this index of the mission (default: append and re-plan)")
    j.add_argument("--priority", type=int, help="mission priority (lower wins; default 2)")
    j.add_argument("--ordered", action="store_true", help="keep the given order (default: let the scheduler order)")
    j.add_argument("--url", help="API url (default: $AERODAAS_HITL_URL or the running server's state file); the "
                   "state file's token goes only to the state file's scheme, host and port: another URL needs its "
                   "own token")
    j.add_argument("--token", help="bearer token (default: $AERODAAS_HITL_TOKEN, or the state file's for its own "
                   "server; a token on the command line is visible to other users in ps)")
    j.add_argument("--cacert", metavar="PEM", help="certificate to trust for an https API (its self-signed certificate "
                   "or its CA; default: $AERODAAS_HITL_CAFILE, the state file's, then the system's CAs)")
    j.add_argument("--insecure-http", action="store_true", help="send the token over plain http to a host off "
                   "loopback (refused otherwise: it crosses the network in clear text)")
    j.add_argument("--json", action="store_true", help="print the API's JSON reply")
    j.set_defaults(func=run)
