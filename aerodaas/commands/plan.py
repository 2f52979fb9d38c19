"""``aerodaas plan APP.py``: the actors an application's run would start and where, without Ray: its options and
its handler :func:`run` (the application loader, the dataflow plan and the placement check are imported when it
runs)."""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
from pathlib import Path


def add_parser(sub) -> None:
    """``aerodaas plan APP.py [--env FILE] [--json]``."""
    pl = sub.add_parser("plan", help="print the actors an application would start and where, without flying")
    pl.add_argument("app")
    pl.add_argument("--env", help="environment.json to use instead of the one the app names")
    pl.add_argument("--json", action="store_true", help="the plan as JSON (actors, nodes, edges)")
    pl.set_defaults(func=run)


def _load_app(args: argparse.Namespace, prog: str):
    """Load ``args.app`` (:func:`aerodaas.runtime.app_loader.load_app`, ``--env`` over the environment it names)
    without Ray; returns the :class:`~aerodaas.runtime.app_loader.Application`, or the exit code after printing why
    not: 2 for bad input (named), 1 for an exception of the app's own code (with its traceback). What the app
    prints goes to standard error."""
    from aerodaas.config import ConfigError  # lazy: CLI start-up (pydantic)
    from aerodaas.runtime.app_errors import report  # lazy: CLI start-up (the runtime)
    from aerodaas.runtime.app_loader import load_app  # lazy: CLI start-up (the app loader, pydantic)

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
    from aerodaas.clusters.placement import placement_warning  # lazy: CLI start-up (the placement rules)
    from aerodaas.runtime.dataflow import Placement  # lazy: CLI start-up (the runtime)

    app = _load_app(args, "aerodaas plan")
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
