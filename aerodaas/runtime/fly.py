"""An application file flown as the process's command (``aerodaas run APP.py``, whose options are checked by
:mod:`aerodaas.commands.run` before this runs): the SIGTERM/SIGINT handling of a mission (one clean stop; a late
signal after the summary keeps the exit code), each mission's summary printed, and the exit code of the missions'
results (the README's table of ``aerodaas run`` exit codes)."""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

from aerodaas.config import ConfigError
from aerodaas.process.state import PROCESS
from aerodaas.runtime import driver as runtime, ray_start
from aerodaas.runtime.app_errors import report
from aerodaas.runtime.options import RunOptions
from aerodaas.runtime.report import format_summary

__all__ = ["StopSignals", "exit_code", "fly"]


class StopSignals:
    """``aerodaas run``'s SIGTERM/SIGINT handling (`kill`, `docker stop`, systemd, Ctrl-C): one clean stop of the
    mission; after a mission's summary, a signal is a late one that does not change the exit code. ``results``:
    the list the run appends each mission's result to (read, never changed)."""

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
        """Put back the handlers :meth:`install` replaced."""
        signal.signal(signal.SIGTERM, self.previous[0])
        signal.signal(signal.SIGINT, self.previous[1])


def exit_code(results: list, stop: list[int]) -> int:
    """``aerodaas run``'s exit code for its missions' results (``MissionResult`` list) and the stop signals it
    received (``stop``, signal numbers; see the README): 1 no mission (said on standard error), 128 + signal for a
    stopped or interrupted one, 2 a vehicle refused our credentials, 3 a drone lost, 4 part of the recording lost,
    5 degraded, else 0 when every mission succeeded and 1 when one failed."""
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


def fly(app: Path, opts: RunOptions, *, own_process: bool = False) -> int:
    """Fly the application file ``app`` with the checked options ``opts`` (the actor classes included:
    :func:`aerodaas.app.api.with_builtin_actors`) through :func:`aerodaas.runtime.driver.run_file`, printing each
    mission's summary; returns :func:`exit_code` (2 for bad input the run refused, named on standard error, 1 for
    an exception of the app's own code, with its traceback). ``own_process``: the process is this command and ends
    when this returns, so the stop-signal handler stays installed and a late signal keeps the exit code."""
    results: list = []
    signals = StopSignals(results)
    signals.install()
    PROCESS.stop.reset()
    runtime.allow_stop_interrupt(True)  # loading the app: a stop may interrupt it at once

    def on_result(res) -> None:  # every mission of the app counts
        results.append(res)
        print(format_summary(res), flush=True)

    try:
        runtime.run_file(str(app), opts, on_result=on_result)
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
        if not (own_process and results):
            signals.restore()
        # else the process is this command and ends now: a signal from here to its exit is a late one, recorded by
        # the handler, and the exit code stays the mission's (restoring the default handler let a SIGTERM sent right
        # after the summary kill the process with -15)
    return exit_code(results, signals.stop)
