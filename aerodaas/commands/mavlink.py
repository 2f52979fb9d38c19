"""``aerodaas mavlink signing setup|remove --connection C --key-file F --secure-link``: provision a vehicle with a
MAVLink 2 signing key, or take it away, with SETUP_SIGNING (MAVLink common.xml; mavlink.io/en/guide/message_signing.html
"Secret Key Management": the key travels in the clear, so only over a link the user declares secure, e.g. USB or a
cable, never a radio), then check the result by a round trip: after ``setup`` the backend connects with the key
(a correctly signed HEARTBEAT, signed acknowledgements: aerodaas/backends/mavlink/signing.py) and a signed command is
acknowledged; after ``remove`` the vehicle's HEARTBEAT comes unsigned and an unsigned command is acknowledged. No Ray,
no environment file. Exit 0 when checked, 2 for bad input (the key file, no ``--secure-link``), 1 when the vehicle
does not answer as it should. The options and the handler :func:`run_signing` are this module (parsed at every
``aerodaas`` start); the work, :mod:`aerodaas.tools.signing_provision`."""
from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_parser", "run_signing"]


def add_parser(sub: Any) -> None:
    """Register ``mavlink signing setup|remove`` on the CLI's sub-parsers ``sub``."""
    mv = sub.add_parser("mavlink", help="MAVLink vehicle tools: signing keys")
    msub = mv.add_subparsers(dest="mavlink_cmd", required=True, metavar="TOOL")
    sg = msub.add_parser("signing", help="provision a vehicle with a MAVLink 2 signing key (SETUP_SIGNING), or "
                                         "remove it, and check the result by a round trip")
    sg.add_argument("action", choices=["setup", "remove"])
    sg.add_argument("--connection", required=True, help="pymavlink connection string (tcp:HOST:PORT, /dev/ttyACM0, ...)")
    sg.add_argument("--key-file", required=True, help="the vehicle's key file: 64 hex characters or 32 raw bytes, "
                                                      "mode 0600 (mavlink.signing_key_file)")
    sg.add_argument("--generate", action="store_true", help="setup: create the key file (a new random key, 0600) "
                                                            "when it does not exist")
    sg.add_argument("--secure-link", action="store_true",
                    help="declare this link secure (USB, a cable): SETUP_SIGNING carries the key in the clear")
    sg.add_argument("--target-system", type=int, default=None, help="the vehicle's system id (default: the first heard)")
    sg.add_argument("--baud", type=int, default=57600)
    sg.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the vehicle at each step")
    sg.set_defaults(func=run_signing)


def run_signing(args: argparse.Namespace) -> int:
    """``aerodaas mavlink signing setup|remove``: :func:`aerodaas.tools.signing_provision.provision`; returns the
    exit code."""
    from aerodaas.tools.signing_provision import SigningRequest, provision  # lazy: CLI start-up (pymavlink, pydantic)

    return provision(SigningRequest(action=args.action, connection=args.connection, key_file=args.key_file,
                                    generate=args.generate, secure_link=args.secure_link,
                                    target_system=args.target_system, baud=args.baud, timeout_s=args.timeout))
