"""The ``aerodaas`` command line: ``run``, ``info``, ``schema``, ``sim``, ``mission`` and more.

Commands with a module of their own register themselves here: ``run`` (:mod:`aerodaas.run_cli`), ``plugins``
(:mod:`aerodaas.plugins_cli`), ``mission`` (:mod:`aerodaas.tools.mission_cli`), ``mavlink``
(:mod:`aerodaas.tools.signing_cli`), ``bench`` (:mod:`aerodaas.bench`)."""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
from pathlib import Path


def _cmd_up(args: argparse.Namespace) -> int:
    """``aerodaas up [--cpus N] [--warm-workers K]``: start the persistent local cluster
    (:mod:`aerodaas.clusters.persistent`) with K warm workers (:mod:`aerodaas.clusters.warm_pool`). Exit 0 (also
    when it already runs), 1 when it cannot start, 2 for a bad ``--cpus`` or ``--warm-workers``."""
    from aerodaas.clusters.persistent import up

    if not 1 <= args.cpus <= 256:
        print(f"aerodaas up: --cpus must be in [1, 256], got {args.cpus}", file=sys.stderr)
        return 2
    if not 0 <= args.warm_workers <= 64:
        print(f"aerodaas up: --warm-workers must be in [0, 64], got {args.warm_workers}", file=sys.stderr)
        return 2
    try:
        st = up(cpus=args.cpus, warm_workers=args.warm_workers)
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    what = "already running" if st["already"] else "started"
    warm = f", {st['warm_workers']} warm workers" if st.get("warm_workers") else ""
    print(f"aerodaas up: local cluster {what} at {st['address']} (pid {st['pid']}, loopback only, tier=edge{warm}"
          + (f", dashboard http://{st['dashboard']}" if st.get("dashboard") else "") + "); `aerodaas run` attaches "
          "to it, `aerodaas down` stops it", flush=True)
    return 0


def _cmd_down(args: argparse.Namespace) -> int:
    """``aerodaas down``: stop the cluster ``aerodaas up`` started (its processes only) and remove the shared
    ground cache (:func:`aerodaas.sim.ground_cache.clear`). Exit 0, 1 if it would not stop."""
    from aerodaas.clusters.persistent import down

    try:
        st = down()
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    print("aerodaas down: " + (f"stopped the local cluster at {st['address']} (pid {st['pid']})" if st else
                               "no local cluster of `aerodaas up` is running"), flush=True)
    from aerodaas.sim import ground_cache

    freed = ground_cache.clear()
    if freed:
        print(f"aerodaas down: removed the shared ground cache at {ground_cache.cache_dir()} "
              f"({freed / 1e6:.1f} MB)", flush=True)
    return 0


def _load(args: argparse.Namespace, prog: str):
    """Load ``args.app`` (:func:`aerodaas.runtime.app_loader.load_app`, ``--env`` over the environment it names)
    without Ray; returns the :class:`~aerodaas.runtime.app_loader.Application`, or the exit code after printing why
    not: 2 for bad input (named), 1 for an exception of the app's own code (with its traceback). What the app
    prints goes to standard error."""
    from aerodaas.config import ConfigError
    from aerodaas.runtime.app_loader import load_app

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
        from aerodaas.runtime.app_errors import report

        return report(e, str(app), prog)


def _cmd_plan(args: argparse.Namespace) -> int:
    """``aerodaas plan APP.py [--env FILE] [--json]``: load the application and print the actors its run would
    start, where each goes (its ``label_selector``) and the edges between them, without starting Ray or flying.
    Exit 0, 2 for bad input (named) like ``aerodaas run``, 1 for an exception of the app's own code (with its
    traceback)."""
    from aerodaas.clusters.placement import placement_warning
    from aerodaas.runtime.dataflow import Placement

    app = _load(args, "aerodaas plan")
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


def _cmd_replay(args: argparse.Namespace) -> int:
    """``aerodaas replay FILE.mcap --live [HOST:PORT] [--speed K]``: serve a recording to Foxglove over WebSocket
    (:func:`aerodaas.liveview.server.replay`). Exit 0 when played to the end or stopped (Ctrl-C, SIGTERM), 2 for a bad file,
    address or speed."""
    from aerodaas.liveview.server import check_bindable, live_access, parse_address, replay, write_live_state

    try:
        host, port = parse_address(args.live)
        check_bindable(host, port)
        access = live_access(host, args.tls_cert, args.tls_key, bool(args.insecure))
        if not args.speed > 0:
            raise ValueError(f"--speed must be a positive number (1 = as recorded), got {args.speed!r}")
        if not Path(args.file).is_file():
            raise FileNotFoundError(f"recording {args.file!r} not found")
    except (ValueError, FileNotFoundError) as e:
        print(f"aerodaas replay: {e}", file=sys.stderr)
        return 2

    def on_sigterm(signum, frame):  # the same clean stop as Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt(f"signal {signum}")

    def ready(server) -> None:
        wait = "" if args.no_wait else "; playback starts when a client subscribes"
        token = f"; token in {write_live_state(server.url, access)}, owner only" if access.token else ""
        print(f"aerodaas replay: serving {args.file} at {server.url} ({args.speed:g}x){wait}{token}", flush=True)
        if access.insecure:
            print(f"aerodaas replay: WARNING: serving plain WebSocket off loopback ({server.url}, --insecure): the "
                  f"recording can be read on the network", file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        out = replay(args.file, args.live, speed=args.speed, on_ready=ready, access=access,
                     wait_for_client_s=None if args.no_wait else float("inf"))
    except KeyboardInterrupt:
        print("aerodaas replay: stopped", file=sys.stderr, flush=True)
        return 0
    except (OSError, ValueError, RuntimeError) as e:
        print(f"aerodaas replay: {e}", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGTERM, previous)
    insecure = "; INSECURE: served in clear text off loopback (--insecure)" if access.insecure else ""
    print(f"aerodaas replay: {out['messages']} messages, {out['duration_s']:.1f} s of recording in "
          f"{out['wall_s']:.1f} s{insecure}", flush=True)
    return 0


def _cmd_layout(args: argparse.Namespace) -> int:
    """``aerodaas layout RUN.mcap [--out FILE]``: a Foxglove layout for the recording's robot, camera and detections
    (:func:`aerodaas.liveview.layout.layout_for_recording`); exit 2 for a missing or foreign file."""
    from aerodaas.liveview.layout import layout_for_recording

    try:
        text = json.dumps(layout_for_recording(args.file), indent=2) + "\n"
        if args.out:
            Path(args.out).write_text(text)
            print(f"aerodaas layout: wrote {args.out} (Foxglove: Layouts -> Import from file)")
        else:
            sys.stdout.write(text)
    except (OSError, ValueError) as e:
        print(f"aerodaas layout: {e}", file=sys.stderr)
        return 2
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from aerodaas.recording.video_summary import format_video_streams, video_streams
    from aerodaas.recording.writer import summarize_mcap

    try:
        s = summarize_mcap(args.file)
        s["video"] = video_streams(args.file, s["channels"])  # stream cameras: counters, capture-to-hand-off
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
    acc = s.get("accounting")
    if acc is not None:  # per channel: the producers' sequence numbers against the file's messages
        print(f"accounting: {acc['lost_total']} numbered messages lost" + (":" if acc["lost"] else ""))
        for topic, n in acc["lost"].items():
            c = acc["channels"][topic]
            print(f"  {topic:<{w}}  {n} lost, {c['recorded']} of {c['produced'] - c['duplicates']} recorded")
    if s["video"]:
        print("\n".join(["video streams:"] + format_video_streams(s["video"])))
    return 0


def _parse_waypoint(text: str) -> dict:
    """``x,y,z[,hover]`` (ENU metres from home, hover seconds) -> a waypoint request dict."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (3, 4):
        raise argparse.ArgumentTypeError(f"--waypoint expects x,y,z[,hover] (metres, seconds), got {text!r}")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--waypoint expects numbers x,y,z[,hover], got {text!r}") from None
    wp = {"x": vals[0], "y": vals[1], "z": vals[2]}
    if len(vals) == 4:
        wp["hover_duration"] = vals[3]
    return wp


def _cmd_inject(args: argparse.Namespace) -> int:
    from aerodaas.tools.hitl import request

    body: dict = {"waypoints": args.waypoint, "scheduling_type": "ORDERED" if args.ordered else "UNORDERED"}
    if args.index is not None:
        body["index"] = args.index
    if args.priority is not None:
        body["priority"] = args.priority
    try:
        status, out = request("POST", f"/drones/{args.drone}/waypoints", body, url=args.url, token=args.token,
                              cafile=args.cacert)
    except RuntimeError as e:
        print(f"aerodaas inject: {e}", file=sys.stderr)
        return 2
    if status != 200:
        detail = out.get("detail") if isinstance(out, dict) else out
        if isinstance(detail, list):
            detail = "; ".join(f"{'.'.join(str(x) for x in d.get('loc', []))}: {d.get('msg')}" for d in detail)
        print(f"aerodaas inject: HTTP {status}: {detail}", file=sys.stderr)
        return 1
    print(json.dumps(out, indent=2) if args.json else f"queued {', '.join(out['added'])} for {args.drone}")
    return 0


def _cmd_sim(args: argparse.Namespace) -> int:
    """``aerodaas sim --mavlink ADDR``: the flight model as an ArduPilot/PX4 vehicle until Ctrl-C or SIGTERM
    (``kill``, ``docker stop``, systemd), either of which stops it cleanly: sockets closed, exit code 0 (stopping
    is how a server ends, unlike ``run``'s interrupted mission); 2 for a bad argument or address."""
    import time

    from aerodaas.emulators.mavlink_vehicle import MavlinkVehicleEmulator
    from aerodaas.model.types import GeoPoint

    home = None
    if args.home:
        try:
            lat, lon, alt = (float(v) for v in args.home.split(","))
            home = GeoPoint(lat=lat, lon=lon, alt=alt)
        except ValueError as e:
            print(f"aerodaas sim: --home expects LAT,LON,ALT (degrees, degrees, metres AMSL), got {args.home!r} "
                  f"({e})", file=sys.stderr)
            return 2
    try:
        emu = MavlinkVehicleEmulator(args.autopilot, home=home, speedup=args.speedup, system_id=args.sysid)
        address = emu.start(args.mavlink, allow_remote=args.allow_remote)
    except (ValueError, OSError) as e:
        print(f"aerodaas sim: {e}", file=sys.stderr)
        return 2

    def on_sigterm(signum, frame):  # the same clean stop as Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # one clean stop; a second SIGTERM must not cut it short
        raise KeyboardInterrupt(f"signal {signum}")

    previous_sigterm = None
    try:
        try:
            previous_sigterm = signal.signal(signal.SIGTERM, on_sigterm)
        except ValueError:  # not the main thread (main() called from a worker thread): Ctrl-C only
            pass
        print(f"aerodaas sim: {args.autopilot} vehicle (system {args.sysid}) on {address}, {args.speedup:g}x real "
              "time; Ctrl-C or SIGTERM to stop", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("aerodaas sim: stopped", file=sys.stderr, flush=True)
        return 0
    finally:
        if previous_sigterm is not None:  # no signal may cut the clean stop short
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        emu.stop()
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)


def _cmd_recover(args: argparse.Namespace) -> int:
    """``aerodaas recover FILE [--out OUT]``: see :mod:`aerodaas.recording.recover`; a recording in segments (its
    recorder actor was restarted: ``FILE``, ``FILE.1.mcap`` ...) is joined into one file
    (:func:`aerodaas.recording.segments.join_segments`). Exit 0 (also for a file that was already finished), 2 for a
    missing or non-MCAP file or an output that cannot be written."""
    from aerodaas.recording.recover import recover_mcap
    from aerodaas.recording.segments import join_segments, list_segments

    try:
        if len(list_segments(args.file)) > 1:
            j = join_segments(args.file, args.out)
            print(f"{j['out']}: {len(j['segments'])} segments ({', '.join(j['segments'])}) joined, finished and "
                  f"indexed: {j['messages']} messages on {j['channels']} channels")
            return 0
        r = recover_mcap(args.file, args.out)
    except (OSError, ValueError) as e:
        print(f"aerodaas recover: {e}", file=sys.stderr)
        return 2
    if r["was_finished"] and r["messages"] is None:
        print(f"{r['path']}: already finished; nothing to do")
    else:
        print(f"{r['out']}: finished and indexed, {r['messages']} messages on {r['channels']} channels recovered")
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    from aerodaas.config import json_schema

    print(json.dumps(json_schema(), indent=2))
    return 0


def console() -> int:
    """The ``aerodaas`` command (console script and ``python -m aerodaas.cli``): :func:`main` as the process's own
    command, whose late-signal handler then stays installed until the process exits."""
    return main(own_process=True)


def _add_run_parsers(sub) -> None:
    """``run`` (:mod:`aerodaas.run_cli`), ``up``, ``down`` and ``plan``."""
    from aerodaas.run_cli import add_parser as _add_run_parser

    _add_run_parser(sub)
    upp = sub.add_parser("up", help="start a persistent local Ray cluster (loopback, token auth, tier=edge, "
                                     "dashboard) that `aerodaas run` attaches to")
    upp.add_argument("--cpus", type=int, default=3, help="logical CPUs of the node (sizes the prestarted workers)")
    from aerodaas.clusters.persistent import DEFAULT_WARM_WORKERS

    upp.add_argument("--warm-workers", type=int, default=DEFAULT_WARM_WORKERS,
                     help="idle workers kept with the framework imported, for the next run's actors (0: none)")
    upp.set_defaults(func=_cmd_up)
    sub.add_parser("down", help="stop the cluster `aerodaas up` started (only that one)").set_defaults(func=_cmd_down)
    pl = sub.add_parser("plan", help="print the actors an application would start and where, without flying")
    pl.add_argument("app")
    pl.add_argument("--env", help="environment.json to use instead of the one the app names")
    pl.add_argument("--json", action="store_true", help="the plan as JSON (actors, nodes, edges)")
    pl.set_defaults(func=_cmd_plan)


def _add_recording_parsers(sub) -> None:
    """``replay``, ``layout``, ``info``, ``schema``, ``plugins`` and ``recover``."""
    rp = sub.add_parser("replay", help="serve an MCAP recording to Foxglove over WebSocket, at 1x or faster")
    rp.add_argument("file")
    rp.add_argument("--live", nargs="?", const="", required=True, metavar="HOST:PORT",
                    help="address to serve on (default 127.0.0.1:8765; port 0: any free port)")
    rp.add_argument("--speed", type=float, default=1.0, help="playback speed over the recorded time (default 1)")
    rp.add_argument("--no-wait", action="store_true", help="start at once instead of when a client subscribes")
    rp.add_argument("--tls-cert", metavar="PEM", help="certificate (chain): serve WSS (needed off loopback)")
    rp.add_argument("--tls-key", metavar="PEM", help="private key of --tls-cert (mode 0600)")
    rp.add_argument("--insecure", action="store_true", help="serve plain WebSocket off loopback (no certificate)")
    rp.set_defaults(func=_cmd_replay)
    ly = sub.add_parser("layout", help="write a Foxglove layout (camera + detections, 3D, map, state, battery/altitude) "
                                       "for a recording")
    ly.add_argument("file")
    ly.add_argument("--out", metavar="FILE", help="output file (default: standard output)")
    ly.set_defaults(func=_cmd_layout)
    i = sub.add_parser("info", help="summarise an MCAP recording")
    i.add_argument("file")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_cmd_info)
    s = sub.add_parser("schema", help="print the JSON Schema of environment.json")
    s.set_defaults(func=_cmd_schema)
    from aerodaas.plugins_cli import add_parser as _add_plugins_parser
    from aerodaas.train_cli import add_parser as _add_train_parser

    _add_plugins_parser(sub)
    _add_train_parser(sub)
    rc = sub.add_parser("recover", help="rewrite an unfinished (crashed, killed) MCAP recording as a finished, "
                                        "indexed one")
    rc.add_argument("file")
    rc.add_argument("--out", help="write here instead of replacing FILE")
    rc.set_defaults(func=_cmd_recover)


def _add_tool_parsers(sub) -> None:
    """``inject``, ``plot``, ``sim``, ``mission`` and ``bench``."""
    j = sub.add_parser("inject", help="add waypoints to a running mission through the human-in-the-loop API")
    j.add_argument("--drone", required=True, help="robot id")
    j.add_argument("--waypoint", required=True, action="append", type=_parse_waypoint,
                   help="x,y,z[,hover]: ENU metres from home and hover seconds (repeatable)")
    j.add_argument("--index", type=int, help="insert at this index of the mission (default: append and re-plan)")
    j.add_argument("--priority", type=int, help="mission priority (lower wins; default 2)")
    j.add_argument("--ordered", action="store_true", help="keep the given order (default: let the scheduler order)")
    j.add_argument("--url", help="API url (default: $AERODAAS_HITL_URL or the running server's state file)")
    j.add_argument("--token", help="bearer token (default: $AERODAAS_HITL_TOKEN or the state file)")
    j.add_argument("--cacert", metavar="PEM", help="certificate to trust for an https API (its self-signed certificate "
                   "or its CA; default: $AERODAAS_HITL_CAFILE, the state file's, then the system's CAs)")
    j.add_argument("--json", action="store_true", help="print the API's JSON reply")
    j.set_defaults(func=_cmd_inject)
    pl = sub.add_parser("plot", help="draw a recording's figures (trajectory, battery/altitude, latency) as PNGs")
    pl.add_argument("file", help="MCAP recording (an unfinished, crashed one plots what is readable)")
    pl.add_argument("--out", metavar="DIR", help="output folder (default: <stem>_plots/ next to the recording)")

    def _cmd_plot(a: argparse.Namespace) -> int:
        from aerodaas.tools.plot import cmd_plot  # matplotlib is imported only for this command

        return cmd_plot(a)

    pl.set_defaults(func=_cmd_plot)
    sm = sub.add_parser("sim", help="serve the simulator as a MAVLink vehicle (ArduPilot or PX4 behaviour)")
    sm.add_argument("--mavlink", required=True, metavar="ADDR",
                    help="tcp:HOST:PORT (server), udpin:HOST:PORT or udpout:HOST:PORT, e.g. tcp:127.0.0.1:5760")
    sm.add_argument("--autopilot", choices=["ardupilot", "px4"], default="ardupilot")
    sm.add_argument("--speedup", type=float, default=1.0, help="vehicle time runs K times faster than real time")
    sm.add_argument("--home", metavar="LAT,LON,ALT", help="home position (degrees, degrees, metres AMSL)")
    sm.add_argument("--sysid", type=int, default=1, help="MAVLink system id (default 1)")
    sm.add_argument("--allow-remote", action="store_true", help="allow a non-loopback address")
    sm.set_defaults(func=_cmd_sim)
    from aerodaas.tools.mission_cli import add_parser as _add_mission_parser

    _add_mission_parser(sub)
    from aerodaas.tools.signing_cli import add_parser as _add_signing_parser

    _add_signing_parser(sub)
    bench = sub.add_parser("bench", help="benchmarks: tours, schedulers, overhead, fleet, startup, tello-video, raypath; "
                                         "--json for JSON output")
    from aerodaas.bench import add_parsers as _add_bench_parsers  # each benchmark registers its own sub-command

    _add_bench_parsers(bench.add_subparsers(dest="bench_cmd", required=True, metavar="BENCHMARK"))


def main(argv: list[str] | None = None, *, own_process: bool = False) -> int:
    """The ``aerodaas`` command line (``argv``: its arguments; default ``sys.argv[1:]``); returns the exit code."""
    p = argparse.ArgumentParser(prog="aerodaas", description="AeroDaaS: drones-as-a-service on Ray")
    sub = p.add_subparsers(dest="cmd", required=True)
    _add_run_parsers(sub)
    _add_recording_parsers(sub)
    _add_tool_parsers(sub)
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["inject"]:  # its values may start with '-' (a token, a waypoint south-west of home)
        from aerodaas.tools.hitl import inject_argv

        argv = inject_argv(argv)
    args = p.parse_args(argv)
    args.own_process = own_process  # read by `aerodaas run` (its late-signal handler stays installed to the exit)
    try:
        return args.func(args)
    except BrokenPipeError:  # `aerodaas info FILE | head`: the reader left; end quietly like any Unix filter
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())  # Python's final flush of stdout must not fail again
        except OSError:
            pass
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(console())
