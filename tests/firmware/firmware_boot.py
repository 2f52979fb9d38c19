"""Inside a SITL network namespace, before the test's steps: wait for each firmware instance's first HEARTBEAT and
restart an instance that never sends one (``python -m tests.firmware.firmware_boot SPEC.json PID0 PID1 ...``).

Why: a fresh ArduCopter SITL instance, started beside two others on a loaded 2-core machine, once stopped during
its own start-up (its log ended after the second "Loaded defaults" line, its storage was never written again, and
for 120 s it sent nothing; 2026-11-27, the three-vehicle signing fleet, in CI and once beside two CPU burners). That
is the firmware binary's start-up, not a behaviour any test is about, so the harness starts such an instance again
(with the same command, its first log kept as ``fw<i>.log.boot<k>``) and says so on standard error and in
``boot.log`` beside the logs. What the tests judge begins after this: every vehicle up and sending.

Standard output: ``FW<i>=<pid>`` for each restarted instance, for the script to ``eval`` (its ``$FW<i>`` then names
the running firmware). Exit 1 when an instance sent no HEARTBEAT after :data:`ATTEMPTS` starts."""
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


def _heartbeat(connection: str, timeout_s: float) -> bool:
    """Whether a HEARTBEAT arrived on ``connection`` (a pymavlink ``udpin:`` string) within ``timeout_s``."""
    from pymavlink import mavutil

    link = mavutil.mavlink_connection(connection)
    try:
        return link.recv_match(type="HEARTBEAT", blocking=True, timeout=timeout_s) is not None
    finally:
        link.close()


def _describe(pid: int) -> str:
    """The process state of ``pid`` (``/proc``), for the boot log."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text().split()
    except OSError:
        return f"pid {pid} has exited"
    return f"pid {pid} state {stat[2]}, CPU {(int(stat[13]) + int(stat[14])) / os.sysconf('SC_CLK_TCK'):.1f} s"


def boot_check(starts: list[tuple[str, Path, str]], spec: Path) -> str:
    """A shell line that runs this check on the instances ``starts`` started (``(the command that starts it in the
    background, its log, its pymavlink connection)``, instance i's pid in ``$FW<i>``), its spec written to ``spec``,
    and evaluates the ``FW<i>=pid`` lines it prints."""
    spec.write_text(json.dumps([{"instance": i, "connection": conn, "command": c, "log": str(log)}
                                for i, (c, log, conn) in enumerate(starts)]))
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
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], [int(p) for p in sys.argv[2:]]))
