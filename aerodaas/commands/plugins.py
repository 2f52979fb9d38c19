"""``aerodaas plugins [--json] [--kind KIND] [--app APP.py]``: every registered plug-in with its kind, name,
origin (builtin / decorator in FILE / import path / entry point DIST) and class. Its options (this module) are
parsed without the registry, which is imported when the command runs (:mod:`aerodaas.commands.plugins_main`)."""
from __future__ import annotations

import argparse


def add_parser(sub) -> None:
    """Register the ``plugins`` sub-command on the CLI's sub-parsers ``sub``."""
    pp = sub.add_parser("plugins", help="list every registered plug-in (backends, sensors, analytics, trajectory and "
                                        "analytics schedulers) with its kind and origin")
    pp.add_argument("--json", action="store_true", help="a JSON list instead of a table")
    pp.add_argument("--kind", type=plugin_kind, help="only this kind (backend, sensor, analytics, ...: the kinds of "
                                                      "aerodaas.plugins.registry.KINDS)")
    pp.add_argument("--app", metavar="FILE.py", help="load this application first (its decorators register plug-ins; "
                                                      "its mission is not flown)")
    pp.set_defaults(func=cmd_plugins)


def plugin_kind(text: str) -> str:
    """``argparse`` type of ``--kind``: one of :data:`aerodaas.plugins.registry.KINDS`, checked when given (the
    registry is not imported to build the parser). Raises argparse.ArgumentTypeError naming the value and the
    kinds."""
    from aerodaas.plugins.registry import KINDS  # lazy: CLI start-up (the plug-in package imports NumPy)

    if text not in KINDS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {', '.join(KINDS)})")
    return text


def cmd_plugins(args: argparse.Namespace) -> int:
    """``aerodaas plugins``: :func:`aerodaas.commands.plugins_main.cmd_plugins` (exit 0, 2 if ``--app`` cannot be
    loaded)."""
    from aerodaas.commands.plugins_main import cmd_plugins as list_plugins  # lazy: CLI start-up (the registry)

    return list_plugins(args)
