"""What the fault cases (:mod:`aerodaas.reliability.faults`, :mod:`aerodaas.reliability.accounting_faults`) share:
the repository's applications, ``aerodaas`` as a child process and what to read from it (its output, its files with
the ``mcap`` package's own reader, its Ray worker processes by title)."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from aerodaas.clusters.reaper import descendants

REPO_APPS = Path(__file__).resolve().parents[2] / "apps"


def mcap_reader_ok(path: str | Path) -> tuple[bool, int, str]:
    """(mcap's standard seeking reader accepts the file: summary present and every message iterable, message count,
    reason). The reader is the ``mcap`` package's, not ours."""
    try:
        with open(path, "rb") as f:
            r = make_reader(f)
            summ = r.get_summary()
            if summ is None:
                return False, 0, "no summary (unfinished file)"
            n = sum(1 for _ in r.iter_messages())
            return n == summ.statistics.message_count, n, "ok"
    except Exception as e:  # noqa: BLE001 - any reader failure is the verdict
        return False, 0, f"{type(e).__name__}: {e}"


def run_cli(args: list[str], env: dict | None = None, **kw: Any) -> subprocess.Popen:
    """``python -m aerodaas.cli ARGS`` as a child process (stdout and stderr merged, text: bytes that are not text
    in the locale's encoding read as U+FFFD), ``env`` over ours."""
    return subprocess.Popen([sys.executable, "-m", "aerodaas.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, errors="replace", env={**os.environ, **(env or {})},
                            **kw)


class OutputTail:
    """The output of a :func:`run_cli` process, read line by line on a thread while the process runs, so a fault
    case can act on what it prints (:meth:`lines`) and still get all of it at the end (:meth:`finish`)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc
        self._lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True, name="output-tail")
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self._lines.append(line)

    def lines(self) -> list[str]:
        """The lines printed so far."""
        return list(self._lines)

    def finish(self, timeout_s: float) -> str:
        """Everything the process printed, once it ended (the process alone killed after ``timeout_s`` s). What it
        printed is complete once every process holding its output has closed it; a descendant that keeps it open
        (a Ray process left behind) cuts the read 30 s after the process ended."""
        try:
            self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._reader.join(timeout=30)
        if not self._reader.is_alive():
            self.proc.stdout.close()
        return "".join(self._lines)


def wait_size(path: Path, size: int, proc: subprocess.Popen, limit_s: float = 480.0) -> bool:
    """True once ``path`` holds at least ``size`` bytes; False when ``proc`` ended first or after ``limit_s``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        if proc.poll() is not None:
            return False
        if path.exists() and path.stat().st_size >= size:
            return True
        time.sleep(0.1)
    return False


def no_crash(out: str) -> bool:
    """True when a command's output shows no traceback, abort or core dump."""
    return "Traceback" not in out and "Aborted" not in out and "core dumped" not in out


def argv0(pid: int) -> str | None:
    """The first word of ``pid``'s command line (Ray titles its workers ``ray::<Class>...``), None when gone."""
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
    except OSError:
        return None


def actor_pids(root: int, actor_class: str) -> list[int]:
    """Pids of the Ray worker processes below ``root`` that hold an actor of ``actor_class`` (Ray titles them
    ``ray::<Class>``)."""
    return [pid for pid in descendants(root) if (argv0(pid) or "").startswith(f"ray::{actor_class}")]


def summary_outcome(out: str) -> str:
    """The summary's ``mission outcome: ...`` word plus 'ok' when the run was reported as a success."""
    line = next((ln for ln in out.splitlines() if ln.startswith("mission outcome:")), "")
    return line
