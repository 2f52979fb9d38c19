"""``aerodaas plugins [--json] [--kind KIND] [--app APP.py]``: every registered plug-in with its kind, name,
origin (builtin / decorator in FILE / import path / entry point DIST) and class. Its options are parsed without
the registry, which its handler :func:`run` imports when the command runs (:mod:`aerodaas.plugins.registry`)."""
from __future__ import annotations

import argparse
import contextlib
import json
import sys


def add_parser(sub) -> None:
    """Register the ``plugins`` sub-command on the CLI's sub-parsers ``sub``."""
    pp = sub.add_parser("plugins", help="list every registered plug-in (backends, sensors, analytics, trajectory and "
                                        "analytics schedulers) with its kind and origin")
    pp.add_argument("--json", action="store_true", help="a JSON list instead of a table")
    pp.add_argument("--kind", type=plugin_kind, help="only this kind (backend, sensor, analytics, ...: the kinds of "
                                                      "aerodaas.plugins.registry.KINDS)")
    pp.add_argument("--app", metavar="FILE.py", help="load this application first (its decorators register plug-ins; "
                                                      "its mission is not flown)")
    pp.set_defaults(func=run)


def plugin_kind(text: str) -> str:
    """``argparse`` type of ``--kind``: one of :data:`aerodaas.plugins.registry.KINDS`, checked when given (the
    registry is not imported to build the parser). Raises argparse.ArgumentTypeError naming the value and the
    kinds."""
    from aerodaas.plugins.registry import KINDS  # lazy: CLI start-up (the plug-in package imports NumPy)

    if text not in KINDS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {', '.join(KINDS)})")
    return text


def run(args: argparse.Namespace) -> int:
    """``aerodaas plugins``: print the registry (:func:`aerodaas.plugins.registry.describe_all`) as a table or JSON;
    exit code 2 if ``--app`` cannot be loaded (:func:`aerodaas.runtime.app_loader.load_app`: never starts Ray)."""
    from rich.console import Console  # lazy: CLI start-up (rich)
    from rich.table import Table  # lazy: CLI start-up (rich)

    from aerodaas.plugins.registry import describe_all  # lazy: CLI start-up (the plug-in package imports NumPy)
    from aerodaas.runtime.app_loader import load_app  # lazy: CLI start-up (the app loader, pydantic)

    if args.app:  # loaded as `aerodaas run` loads it (one module name): no Ray, its mission only marked, not flown

        try:
            with contextlib.redirect_stdout(sys.stderr):  # the app's own prints: not in the listing (--json)
                load_app(args.app)
        except Exception as e:  # noqa: BLE001
            print(f"error: --app {args.app!r}: {type(e).__name__}: {e}", file=sys.stderr)
            return 2
    rows = describe_all(args.kind)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0

    t = Table(title=f"{len(rows)} plug-ins")
    for c in ("kind", "name", "origin", "class", "config"):
        t.add_column(c)
    for r in rows:
        t.add_row(r["kind"], r["name"], r["origin"], r["class"] + (f" [red]({r['error']})[/red]" if "error" in r else ""),
                  ", ".join(r.get("config", [])))
    Console(width=160).print(t)
    return 0
