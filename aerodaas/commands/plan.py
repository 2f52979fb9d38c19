"""``aerodaas plan``: its options and handler (the command itself: :mod:`aerodaas.commands.plan_main`)."""
from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    """``aerodaas plan APP.py [--env FILE] [--json]``."""
    pl = sub.add_parser("plan", help="print the actors an application would start and where, without flying")
    pl.add_argument("app")
    pl.add_argument("--env", help="environment.json to use instead of the one the app names")
    pl.add_argument("--json", action="store_true", help="the plan as JSON (actors, nodes, edges)")
    pl.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """``aerodaas plan APP.py``: :func:`aerodaas.commands.plan_main.run` (exit 0, 2 for bad input, 1 for the app's
    own exception)."""
    from aerodaas.commands.plan_main import run as plan  # lazy: CLI start-up (the app loader, pydantic)

    return plan(args)
