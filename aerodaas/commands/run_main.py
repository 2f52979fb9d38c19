"""``aerodaas run APP.py`` itself (its options: :mod:`aerodaas.commands.run`): its flags checked into the run's
options before Ray starts, the SIGTERM/SIGINT handling of a mission (one clean stop; a late signal after the summary
keeps the exit code), and the exit code of the missions' results."""
from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from aerodaas.app.api import with_builtin_actors
from aerodaas.config import ConfigError
from aerodaas.process.state import PROCESS
from aerodaas.runtime import driver as runtime, ray_start
from aerodaas.runtime.report import format_summary
from aerodaas.runtime.app_errors import report
from aerodaas.runtime.options import RunOptions
from aerodaas.runtime.preflight import check_run_flags


def _run_options(args: argparse.Namespace) -> "RunOptions | int":
    """``aerodaas run``'s flags as the run's options, every one checked before Ray starts (exit 2 naming the bad
    input: the returned int)."""
    try:
        check_run_flags(args.record, args.env, args.speedup, args.timeout, args.hitl_port, args.address,
                        app=str(args.app), overwrite=args.overwrite)
    except (ConfigError, ValueError) as e:
        print(f"aerodaas run: {e}", file=sys.stderr)
        return 2
    live = access = None
    if args.live is not None:
        from aerodaas.liveview.server import check_bindable, live_access, parse_address  # lazy: --live only (cv2)

        try:
            host, port = parse_address(args.live)
            if not args.address:  # local run: the edge host (which serves) is on this machine
                check_bindable(host, port)
            access = live_access(host, args.tls_cert, args.tls_key, bool(args.insecure))
        except ValueError as e:
            print(f"aerodaas run: {e}", file=sys.stderr)
            return 2
        live = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    return RunOptions(record=args.record, speedup=args.speedup, timeout=args.timeout, address=args.address,
                      overwrite=bool(args.overwrite), env_path=str(Path(args.env).resolve()) if args.env else None,
                      lockstep=True if args.lockstep else None, recorder_hold_s=args.recorder_hold, dashboard=bool(getattr(args, "dashboard", False)),
                      progress=not args.quiet, hitl=True if args.hitl else None, hitl_port=args.hitl_port, live=live,
                      live_access=access, tls_cert=args.tls_cert, tls_key=args.tls_key, insecure=bool(args.insecure))


class _StopSignals:
    """``aerodaas run``'s SIGTERM/SIGINT handling (`kill`, `docker stop`, systemd, Ctrl-C): one clean stop of the
    mission; after a mission's summary, a signal is a late one that does not change the exit code."""

    def __init__(self, results: list) -> None:
        self.results = results
        self.stop: list[int] = []
        self.late: list[int] = []
        self.previous: tuple = ()

    def __call__(self, signum, frame) -> None:
        # Ray's C++ failure-signal handler (absl, chained before this one) answers SIGTERM with alarm(3) and a SIGALRM
        # handler that aborts: the clean stop takes longer than 3 s, so the run died with SIGABRT (exit 134). We take
        # the signal over: cancel that alarm and its handler.
        signal.alarm(0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        if self.results and not PROCESS.stop.in_mission:
            # after the summary (the app ending, Ray shutting down): no KeyboardInterrupt from inside ray.shutdown,
            # and the exit code stays the mission's; a further mission of the app does not start (PROCESS.stop).
            # A second late signal is the user insisting (a hang on the way out): it ends the process as usual
            if self.late:
                signal.signal(signum, signal.SIG_DFL)
                os.kill(os.getpid(), signum)
                return
            self.late.append(signum)
            PROCESS.stop.record(signum)
            return
        self.stop.append(signum)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # one clean stop; a second signal must not cut it short
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        runtime.request_stop(signum)  # raises KeyboardInterrupt where that is safe, else stops at the next safe point

    def install(self) -> None:
        """Installed before Ray starts: the driver's own fatal-signal handler then chains to this one."""
        self.previous = (signal.signal(signal.SIGTERM, self), signal.signal(signal.SIGINT, self))

    def restore(self) -> None:
        signal.signal(signal.SIGTERM, self.previous[0])
        signal.signal(signal.SIGINT, self.previous[1])


def _exit_code(results: list, stop: list[int]) -> int:
    """``aerodaas run``'s exit code for its missions' results (see the README)."""
    if not results:
        print("aerodaas run: the application never called start_mission()", file=sys.stderr)
        return 1
    if stop or any(r.outcome == "interrupted" for r in results):
        return 128 + (stop[0] if stop else signal.SIGINT)  # the shell's convention: 130 / 143
    if any(r.outcome == "refused" for r in results):
        return 2  # a vehicle refused our credentials (a MAVLink signing key it does not hold): input to fix
    if any(r.outcome == "lost" for r in results):
        return 3  # a drone actor died for good (restarts used up, its node lost): its drones' outcome is "lost"
    if any(getattr(r, "recording_losses", None) or r.outcome == "recording_lost" for r in results):
        return 4  # the recorder actor died or a producer's numbered message is in no segment: part of the run lost
    if any(r.outcome == "degraded" for r in results):
        return 5  # a sensor or an analytics failed more often than its limit (aerodaas.recording.health)
    return 0 if all(r.ok for r in results) else 1


def run(args: argparse.Namespace) -> int:
    """``aerodaas run APP.py`` after :func:`aerodaas.commands.run.cmd_run` marked the CLI's start: load the
    application (:func:`aerodaas.runtime.app_loader.load_app`: no Ray, nothing
    flies; bad input exits 2 before any Ray process exists), then fly it (:func:`aerodaas.runtime.driver.run_file`)
    and print each mission's summary."""
    app = Path(args.app)
    if not app.is_file():
        print(f"aerodaas run: application file {str(app)!r} not found", file=sys.stderr)
        return 2
    opts = _run_options(args)
    if isinstance(opts, int):
        return opts
    results: list = []
    signals = _StopSignals(results)
    signals.install()
    PROCESS.stop.reset()
    runtime.allow_stop_interrupt(True)  # loading the app: a stop may interrupt it at once

    def on_result(res) -> None:  # every mission of the app counts
        results.append(res)
        print(format_summary(res), flush=True)

    try:
        # the run's actors are handed to the runtime (which imports none): the built-in ones
        runtime.run_file(str(app), with_builtin_actors(opts), on_result=on_result)
    except ConfigError as e:
        print(f"aerodaas run: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("aerodaas run: interrupted", file=sys.stderr)
        return 128 + (signals.stop or signals.late or [signal.SIGINT])[0]
    except ray_start.RayStartError as e:
        print(f"aerodaas run: {e}", file=sys.stderr)
        return 2 if isinstance(e, ray_start.RayAddressError) else 1
    except Exception as e:  # noqa: BLE001 - whose is it: the app's own bug (exit 1) or input we refused (exit 2)

        return report(e, str(app), "aerodaas run")
    finally:
        runtime.allow_stop_interrupt(False)  # a signal now is recorded, never raised inside ray.shutdown
        ray_start.shutdown_ray()
        if not (getattr(args, "own_process", False) and results):
            signals.restore()
        # else the process is this command and ends now: a signal from here to its exit is a late one, recorded by
        # the handler, and the exit code stays the mission's (restoring the default handler let a SIGTERM sent right
        # after the summary kill the process with -15)
    return _exit_code(results, signals.stop)
