"""``aerodaas plan`` itself (its options: :mod:`aerodaas.commands.plan`): the actors an application's run would
start and where, without Ray."""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
from pathlib import Path

from aerodaas.clusters.placement import placement_warning
from aerodaas.config import ConfigError
from aerodaas.runtime.app_errors import report
from aerodaas.runtime.app_loader import load_app
from aerodaas.runtime.dataflow import Placement


def load_app_file(args: argparse.Namespace, prog: str):
    """Load ``args.app`` (:func:`aerodaas.runtime.app_loader.load_app`, ``--env`` over the environment it names)
    without Ray; returns the :class:`~aerodaas.runtime.app_loader.Application`, or the exit code after printing why
    not: 2 for bad input (named), 1 for an exception of the app's own code (with its traceback). What the app
    prints goes to standard error."""
    app = Path(args.app)
    if not app.is_file():
        print(f"{prog}: application file {str(app)!r} not found", file=sys.stderr)
        return 2
    try:
        with contextlib.redirect_stdout(sys.stderr):  # the app's own prints: not in the plan's output (--json)
            return load_app(app, str(Path(args.env).resolve()) if getattr(args, "env", None) else None)
    except ConfigError as e:
        print(f"{prog}: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    except Exception as e:  # noqa: BLE001 - the app's own bug (exit 1, its traceback) or input we refused (exit 2)

        return report(e, str(app), prog)


def run(args: argparse.Namespace) -> int:
    """``aerodaas plan APP.py [--env FILE] [--json]``: load the application and print the actors its run would
    start, where each goes (its ``label_selector``) and the edges between them, without starting Ray or flying.
    Exit 0, 2 for bad input (named) like ``aerodaas run``, 1 for an exception of the app's own code (with its
    traceback)."""
    app = load_app_file(args, "aerodaas plan")
    if isinstance(app, int):
        return app
    if app.mission is None:
        print("aerodaas plan: the application never called start_mission()", file=sys.stderr)
        return 2
    plan = app.plan()
    placement = Placement(has_cloud=True, local=False)
    warning = placement_warning(plan)
    if warning:
        print(f"aerodaas plan: warning: {warning}", file=sys.stderr)
    print(json.dumps(plan.describe(placement), indent=2) if args.json else plan.text(placement))
    return 0
