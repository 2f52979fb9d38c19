"""``aerodaas plugins`` itself (its options: :mod:`aerodaas.commands.plugins`): the registry listed as a table or
JSON."""
from __future__ import annotations

import argparse
import contextlib
import json
import sys

from rich.console import Console
from rich.table import Table

from aerodaas.plugins.registry import describe_all
from aerodaas.runtime.app_loader import load_app


def cmd_plugins(args: argparse.Namespace) -> int:
    """Print the registry; exit code 2 if ``--app`` cannot be loaded
    (:func:`aerodaas.runtime.app_loader.load_app`: never starts Ray)."""
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
