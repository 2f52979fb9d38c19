"""``aerodaas plugins [--json] [--kind KIND] [--app APP.py]``: every registered plug-in with its kind, name,
origin (builtin / decorator in FILE / import path / entry point DIST) and class."""
from __future__ import annotations

import argparse
import json


def add_parser(sub) -> None:
    """Register the ``plugins`` sub-command on the CLI's sub-parsers ``sub``."""
    from aerodaas.plugins.registry import KINDS

    pp = sub.add_parser("plugins", help="list every registered plug-in (backends, sensors, analytics, trajectory and "
                                        "analytics schedulers) with its kind and origin")
    pp.add_argument("--json", action="store_true", help="a JSON list instead of a table")
    pp.add_argument("--kind", choices=KINDS, help="only this kind")
    pp.add_argument("--app", metavar="FILE.py", help="load this application first (its decorators register plug-ins; "
                                                      "its mission is not flown)")
    pp.set_defaults(func=cmd_plugins)


def cmd_plugins(args: argparse.Namespace) -> int:
    """Print the registry; exit code 2 if ``--app`` cannot be loaded
    (:func:`aerodaas.runtime.app_loader.load_app`: never starts Ray)."""
    from aerodaas.plugins.registry import describe_all

    if args.app:  # loaded as `aerodaas run` loads it (one module name): no Ray, its mission only marked, not flown
        import contextlib
        import sys

        from aerodaas.runtime.app_loader import load_app

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
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"{len(rows)} plug-ins")
    for c in ("kind", "name", "origin", "class", "config"):
        t.add_column(c)
    for r in rows:
        t.add_row(r["kind"], r["name"], r["origin"], r["class"] + (f" [red]({r['error']})[/red]" if "error" in r else ""),
                  ", ".join(r.get("config", [])))
    Console(width=160).print(t)
    return 0
