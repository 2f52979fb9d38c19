"""The ``aerodaas`` command line: ``run``, ``info``, ``schema``."""
from __future__ import annotations

import argparse
import json
import os
import runpy
import sys
from pathlib import Path


def _cmd_run(args: argparse.Namespace) -> int:
    from . import runtime
    from .config import ConfigError

    app = Path(args.app)
    if not app.is_file():
        print(f"aerodaas run: application file {str(app)!r} not found", file=sys.stderr)
        return 2
    o = runtime.OPTIONS
    o.record, o.speedup, o.timeout, o.address = args.record, args.speedup, args.timeout, args.address
    o.env_path = str(Path(args.env).resolve()) if args.env else None
    o.lockstep = True if args.lockstep else None
    o.progress = not args.quiet
    results = []

    from . import api

    original = api.Robot.start_mission

    def start_mission(self, timeout=None):  # capture results for the summary and exit code
        res = original(self, timeout)
        results.append(res)
        print(runtime.format_summary(res), flush=True)
        return res

    api.Robot.start_mission = start_mission
    sys.path.insert(0, str(app.resolve().parent))
    try:
        runpy.run_path(str(app), run_name="__main__")
    except ConfigError as e:
        print(f"aerodaas run: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("aerodaas run: interrupted", file=sys.stderr)
        return 130
    except (FileNotFoundError, ValueError, KeyError) as e:
        print(f"aerodaas run: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    finally:
        api.Robot.start_mission = original
        runtime.shutdown_ray()
    if not results:
        print("aerodaas run: the application never called start_mission()", file=sys.stderr)
        return 1
    if any(r.outcome == "interrupted" for r in results):
        return 130
    return 0 if all(r.ok for r in results) else 1


def _cmd_info(args: argparse.Namespace) -> int:
    from .recording import summarize_mcap

    try:
        s = summarize_mcap(args.file)
    except (OSError, ValueError) as e:
        print(f"aerodaas info: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(s, indent=2, default=str))
        return 0
    print(f"{s['path']}: {s['message_count']} messages, {s['duration_s']:.1f} s, "
          f"{'finished' if s['finished'] else 'UNFINISHED (recovered what was readable)'}")
    mission = s.get("mission") or {}
    print(f"mission outcome: {mission.get('outcome')}   final state: {mission.get('final_state')}")
    w = max((len(c["topic"]) for c in s["channels"]), default=10)
    for c in s["channels"]:
        print(f"  {c['topic']:<{w}}  {c['schema']:<28} {c['count']:>7} msgs  {c['rate_hz']:7.2f} Hz")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from .config import json_schema

    print(json.dumps(json_schema(), indent=2))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="aerodaas", description="AeroDaaS: drones-as-a-service on Ray")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run an application (APP.py) on the embedded simulator or real drones")
    r.add_argument("app")
    r.add_argument("--env", help="environment.json to use instead of the one the app names")
    r.add_argument("--record", help="write the run to this MCAP file")
    r.add_argument("--speedup", type=float, help="simulation speed-up over real time (default: from the env file)")
    r.add_argument("--lockstep", action="store_true", help="simulated time waits for analytics on every frame")
    r.add_argument("--timeout", type=float, help="wall-clock limit in seconds")
    r.add_argument("--address", help="attach to an existing Ray cluster (e.g. 'auto') instead of starting one")
    r.add_argument("--quiet", action="store_true", help="no live progress")
    r.set_defaults(func=_cmd_run)
    i = sub.add_parser("info", help="summarise an MCAP recording")
    i.add_argument("file")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_cmd_info)
    s = sub.add_parser("schema", help="print the JSON Schema of environment.json")
    s.set_defaults(func=_cmd_schema)
    args = p.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
