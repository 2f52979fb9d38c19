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
    pp.add_argument("--app", metavar="FILE.py", help="import this module first (its decorators register plug-ins)")
    pp.set_defaults(func=cmd_plugins)


def cmd_plugins(args: argparse.Namespace) -> int:
    """Print the registry; exit code 2 if ``--app`` cannot be imported."""
    from aerodaas.plugins.registry import describe_all

    if args.app:
        import importlib.util
        import os
        import sys

        spec = importlib.util.spec_from_file_location("aerodaas_plugins_app", os.path.abspath(args.app))
        if spec is None or spec.loader is None:
            print(f"error: --app {args.app!r}: not a Python file", file=sys.stderr)
            return 2
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod  # so that its classes know their file (the origin "decorator in FILE")
        try:
            spec.loader.exec_module(mod)
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
