"""A benchmark's standard output carries its report alone (``aerodaas bench … --json | jq`` and
``json.load`` must work): everything else a benchmark run prints goes to standard error.

The noise comes from places a benchmark does not control: Ray's log monitor thread in the driver forwards worker
and raylet lines (``(raylet) WARNING: 8 PYTHON worker processes have been started…``) by printing to whatever
``sys.stdout`` is at that moment (``ray/_private/worker.py``: ``print_to_stdstream``; at shutdown also the
de-duplicator's leftovers), and child processes inherit file descriptor 1. :func:`report_only_stdout` therefore
moves both, ``sys.stdout`` and descriptor 1, onto standard error for the whole run, and keeps the real standard
output for :func:`print_report` alone. ``ray.init(log_to_driver=False)`` was not chosen: it would hide the workers'
errors from the user too, and would not cover child processes or our own prints.
"""
from __future__ import annotations

import io
import json
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO

__all__ = ["emit_report", "print_report", "report_only_stdout"]

class _StderrWithReport:
    """What ``sys.stdout`` is inside a :func:`report_only_stdout` block: standard error (``stderr``), to which
    every attribute but ``report`` goes (``write``, ``flush``, ``fileno``, ``encoding``...), carrying the block's
    real standard output ``report``, where :func:`print_report` writes. The report stream thus lives with the
    redirection that needs it and ends with it (no module-level stack of blocks); an inner block's ``sys.stdout``
    replaces it and the outer one is back after the inner block."""

    def __init__(self, stderr: TextIO, report: TextIO) -> None:
        self._stderr = stderr
        self.report = report

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stderr, name)

    def write(self, text: str) -> int:
        """Write ``text`` to standard error."""
        return self._stderr.write(text)

    def flush(self) -> None:
        """Flush standard error."""
        self._stderr.flush()


def _fileno(stream: TextIO | None) -> int | None:
    try:
        return stream.fileno() if stream is not None else None
    except (AttributeError, OSError, io.UnsupportedOperation):  # pytest's capsys, a StringIO
        return None


@contextmanager
def report_only_stdout(*, restore: bool = True) -> Iterator[TextIO]:
    """For the block, ``sys.stdout`` writes to ``sys.stderr`` (:class:`_StderrWithReport`) and file descriptor 1
    is a duplicate of descriptor 2, so that prints of any thread (Ray's log monitor), C code and child processes
    land on standard error; yields the real
    standard output (a stream on a duplicate of the old descriptor 1 when ``sys.stdout`` wrote to it, else the old
    ``sys.stdout`` object itself), which :func:`print_report` writes to. ``restore=False`` leaves the redirection
    in place after the block (the ``aerodaas`` process, which exits next: Ray's own shutdown at exit prints too);
    the report stream is flushed either way. Raises OSError if the descriptors cannot be duplicated."""
    old = sys.stdout
    if old is not None:
        old.flush()
    saved = os.dup(1)
    report: TextIO = (os.fdopen(os.dup(saved), "w", encoding="utf-8", errors="replace")
                      if old is None or _fileno(old) == 1 else old)
    os.dup2(2, 1)
    sys.stdout = _StderrWithReport(sys.stderr, report)  # type: ignore[assignment]
    try:
        yield report
    finally:
        try:
            report.flush()
        except BrokenPipeError:  # the reader left (`| head`): nothing more can reach it; end quietly
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, report.fileno())
            os.close(devnull)
        if restore:
            sys.stdout.flush()
            sys.stdout = old
            os.dup2(saved, 1)
            if report is not old:
                report.close()
        os.close(saved)


def print_report(text: str) -> None:
    """Print a benchmark's report (its JSON document, or its table without ``--json``) and a newline: on the real
    standard output kept by the innermost :func:`report_only_stdout` block (the ``report`` of ``sys.stdout`` in
    one), else on ``sys.stdout``; flushed."""
    out = sys.stdout
    stream = out.report if isinstance(out, _StderrWithReport) else out
    stream.write(text + "\n")
    stream.flush()


def emit_report(report: dict, out: str | None, to_stdout: bool) -> None:
    """Write a benchmark's JSON report (indented) to the file ``out`` (if given) and print it with
    :func:`print_report` (if ``to_stdout``). Raises OSError if ``out`` cannot be written."""
    text = json.dumps(report, indent=2)
    if out:
        with open(out, "w") as f:
            f.write(text)
    if to_stdout:
        print_report(text)
