"""Inside a SITL network namespace, before the test's steps: wait for each firmware instance's first HEARTBEAT and
restart an instance that never sends one (``python -m tests.firmware.firmware_boot SPEC.json PID0 PID1 ...``).

Why: a fresh ArduCopter SITL instance, started beside two others on a loaded 2-core machine, once stopped during
its own start-up (its log ended after the second "Loaded defaults" line, its storage was never written again, and
for 120 s it sent nothing; 2026-11-27, the three-vehicle signing fleet, in CI and once beside two CPU burners). That
is the firmware binary's start-up, not a behaviour any test is about, so the harness starts such an instance again
(with the same command, its first log kept as ``fw<i>.log.boot<k>``) and says so on standard error and in
``boot.log`` beside the logs. What the tests judge begins after this: every vehicle up and sending.

Fast boot (ArduCopter only, an instance's spec with ``"run_speedup"``): the instance was started at a higher speed-up
than its test runs at, and once its EKF has an absolute horizontal position (``EKF_STATUS_REPORT`` flag
``EKF_POS_HORIZ_ABS``: what a GUIDED arm needs, ArduPilot's "Need Position Estimate" pre-arm check) the harness sets
its simulator's clock factor ``SIM_SPEEDUP`` to ``run_speedup`` over the instance's second link and waits until the
firmware echoes it (PARAM_VALUE). What that saves is the wait for GPS lock and EKF alignment (about 40 s of vehicle
time) at a real-time test's speed-up 1; it is MAVProxy's ``sitl_autospeedup`` practice. The second link (serial1)
gets EKF_STATUS_REPORT by MAV_CMD_REQUEST_MESSAGE only (no stream rate is changed).

Standard output: ``FW<i>=<pid>`` for each restarted instance, for the script to ``eval`` (its ``$FW<i>`` then names
the running firmware). Exit 1 when an instance sent no HEARTBEAT after :data:`ATTEMPTS` starts, or when a fast-booted
instance did not confirm its ``SIM_SPEEDUP`` (a test must never run at another speed than it asked for)."""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

#: starts per instance before the harness gives up
ATTEMPTS = 3
#: wall seconds an instance gets for its first HEARTBEAT (a fresh ArduCopter sends one within about 2 s, a PX4 SIH
#: within 10 s, both on a loaded machine)
FIRST_HEARTBEAT_S = 60.0
#: wall seconds a fast-booted instance gets for its position estimate (about 8 s at speed-up 5 on a quiet machine);
#: past them its clock factor is set all the same and the backend's own arming wait takes over
FAST_BOOT_READY_S = 90.0
#: MAVLink: EKF_STATUS_REPORT's id, its flag EKF_POS_HORIZ_ABS, MAV_CMD_REQUEST_MESSAGE, MAV_PARAM_TYPE_REAL32
_EKF_STATUS_REPORT, _EKF_POS_HORIZ_ABS, _REQUEST_MESSAGE, _REAL32 = 193, 16, 512, 9


def _heartbeat(connection: str, timeout_s: float) -> bool:
    """Whether a HEARTBEAT arrived on ``connection`` (a pymavlink ``udpin:`` string) within ``timeout_s``."""
    from pymavlink import mavutil

    link = mavutil.mavlink_connection(connection)
    try:
        return link.recv_match(type="HEARTBEAT", blocking=True, timeout=timeout_s) is not None
    finally:
        link.close()


def fast_boot(monitor: str, run_speedup: float, ready_s: float = FAST_BOOT_READY_S) -> str:
    """Wait on ``monitor`` (a pymavlink ``udpin:`` string: the ArduCopter's serial1) until its EKF has an absolute
    horizontal position or ``ready_s`` wall seconds passed, then set ``SIM_SPEEDUP`` to ``run_speedup`` until the
    firmware echoes that value. Returns a line for the boot log; raises RuntimeError when the value is never echoed
    (within 30 s of asking)."""
    from pymavlink import mavutil

    link = mavutil.mavlink_connection(monitor)
    try:
        hb = link.recv_match(type="HEARTBEAT", blocking=True, timeout=FIRST_HEARTBEAT_S)
        if hb is None:
            raise RuntimeError(f"no HEARTBEAT on {monitor}")
        sysid, compid = hb.get_srcSystem(), hb.get_srcComponent()
        start = time.monotonic()
        ready, asked = None, 0.0
        while ready is None and time.monotonic() - start < ready_s:
            if time.monotonic() - asked > 0.5:
                link.mav.command_long_send(sysid, compid, _REQUEST_MESSAGE, 0, _EKF_STATUS_REPORT, 0, 0, 0, 0, 0, 0)
                asked = time.monotonic()
            msg = link.recv_match(type="EKF_STATUS_REPORT", blocking=True, timeout=0.5)
            if msg is not None and msg.flags & _EKF_POS_HORIZ_ABS:
                ready = time.monotonic() - start
        asked, confirmed = 0.0, False
        deadline = time.monotonic() + 30.0
        while not confirmed and time.monotonic() < deadline:
            if time.monotonic() - asked > 1.0:
                link.mav.param_set_send(sysid, compid, b"SIM_SPEEDUP", float(run_speedup), _REAL32)
                asked = time.monotonic()
            msg = link.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            confirmed = (msg is not None and msg.param_id == "SIM_SPEEDUP"
                         and abs(msg.param_value - run_speedup) < 1e-6)
        if not confirmed:
            raise RuntimeError(f"SIM_SPEEDUP {run_speedup:g} never confirmed on {monitor}")
        when = f"position estimate after {ready:.1f} s wall" if ready is not None else \
            f"no position estimate within {ready_s:g} s wall"
        return f"{when}; SIM_SPEEDUP {run_speedup:g} confirmed"
    finally:
        link.close()


def _describe(pid: int) -> str:
    """The process state of ``pid`` (``/proc``), for the boot log."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text().split()
    except OSError:
        return f"pid {pid} has exited"
    return f"pid {pid} state {stat[2]}, CPU {(int(stat[13]) + int(stat[14])) / os.sysconf('SC_CLK_TCK'):.1f} s"


def boot_check(starts: list[tuple[str, Path, str]], spec: Path,
               fast: list[tuple[str, float]] | None = None) -> str:
    """A shell line that runs this check on the instances ``starts`` started (``(the command that starts it in the
    background, its log, its pymavlink connection)``, instance i's pid in ``$FW<i>``), its spec written to ``spec``,
    and evaluates the ``FW<i>=pid`` lines it prints. ``fast``: per instance ``(its second link, the speed-up to run
    at)`` for a fast boot (:func:`fast_boot`)."""
    entries = [{"instance": i, "connection": conn, "command": c, "log": str(log)}
               for i, (c, log, conn) in enumerate(starts)]
    for entry, (monitor, run_speedup) in zip(entries, fast or [], strict=False):
        entry.update(monitor=monitor, run_speedup=run_speedup)
    spec.write_text(json.dumps(entries))
    pids = " ".join(f"$FW{i}" for i in range(len(starts)))
    return f'eval "$({shlex.quote(sys.executable)} -m tests.firmware.firmware_boot {shlex.quote(str(spec))} {pids})"'


def main(spec_path: str, pids: list[int]) -> int:
    """Check every instance of the spec (a JSON list of ``{"instance", "connection", "command", "log"}``;
    ``command`` starts the instance in the background and is run with bash; ``pids``: the running instances'),
    restarting the silent ones."""
    spec = json.loads(Path(spec_path).read_text())
    boot_log = Path(spec_path).with_name("boot.log")
    failed = []
    for inst, pid in zip(spec, pids, strict=True):
        for attempt in range(1, ATTEMPTS + 1):
            if _heartbeat(inst["connection"], FIRST_HEARTBEAT_S):
                break
            note = (f"firmware instance {inst['instance']}: no HEARTBEAT on {inst['connection']} within "
                    f"{FIRST_HEARTBEAT_S:g} s of start {attempt} ({_describe(pid)})")
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            log = Path(inst["log"])
            if log.exists():
                shutil.copy(log, log.with_name(f"{log.name}.boot{attempt}"))
            if attempt == ATTEMPTS:
                failed.append(inst["instance"])
                note += "; giving up"
            else:
                time.sleep(1.0)  # its ports free again
                out = subprocess.run(["bash", "-c", inst["command"] + "\necho $!"], capture_output=True, text=True,
                                     check=True).stdout.split()
                pid = int(out[-1])
                print(f"FW{inst['instance']}={pid}")
                note += f"; started again as pid {pid}"
            print(note, file=sys.stderr)
            with boot_log.open("a") as f:
                f.write(note + "\n")
        if "run_speedup" in inst and inst["instance"] not in failed:
            try:
                note = f"firmware instance {inst['instance']}: {fast_boot(inst['monitor'], inst['run_speedup'])}"
            except RuntimeError as e:
                failed.append(inst["instance"])
                note = f"firmware instance {inst['instance']}: fast boot failed: {e}"
            print(note, file=sys.stderr)
            with boot_log.open("a") as f:
                f.write(note + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], [int(p) for p in sys.argv[2:]]))
