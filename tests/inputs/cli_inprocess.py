"""The ``aerodaas`` command line run inside the test's own process: :func:`run_cli` calls
:func:`aerodaas.cli.main` (the console script's function) with the arguments, working folder and environment a
subprocess would get, and returns what a subprocess returns (exit code, stdout, stderr).

For the checks of bad input, whose point is the message and the exit code: a subprocess pays an interpreter and the
CLI's imports (about half a CPU-second each) for the same code path. What a subprocess gave for free is done here:

* **Ray is never started or joined**: :func:`aerodaas.runtime.ray_start.init_ray` and ``start_ray_early`` (and
  ``ray.init``, once Ray is imported; ``ray.is_initialized`` then says False, as in a new process) raise
  :class:`RayStartedInProcess`, and :func:`run_cli` fails the test if either was called (a bad-input check that
  reached Ray is a bug, as "exit 2 before Ray" says). ``shutdown_ray`` does nothing during the call: a ``run`` ends
  by shutting Ray down, which here would be the worker's shared session (``ray_session``).
* **Nothing leaks into the tests that follow**: the environment variables, working folder, ``sys.path``,
  ``sys.argv``, the signal handlers of SIGINT/SIGTERM/SIGALRM, the two module-level states of the framework (the
  plug-in registry :data:`aerodaas.plugins.registry.REGISTRY` and :data:`aerodaas.process.state.PROCESS`, see
  docs/architecture.md) and the root logger's handlers are put back; the modules the call imported from outside
  the installed packages and this checkout (the app file run as ``aerodaas_app_<stem>``, the plug-in modules next
  to it) are forgotten, as they would be with the subprocess.

With ``shared_ray``, an ``aerodaas run`` that flies uses the pytest worker's shared Ray session instead of starting
one of its own (see :func:`run_cli`).

The few tests that prove the whole command end to end (exit code 2 from the real process, no Ray session in a fresh
``RAY_TMPDIR``) keep a subprocess."""
from __future__ import annotations

import contextlib
import copy
import io
import logging
import os
import signal
import site
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
#: folders whose modules are the installed packages or this checkout's: kept in ``sys.modules`` after a call
_KEPT_ROOTS = tuple({str(Path(p).resolve()) + os.sep for p in (sys.prefix, sys.base_prefix, sys.exec_prefix,
                                                                site.USER_BASE or sys.prefix, REPO)})
_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGALRM)

__all__ = ["CliResult", "RayStartedInProcess", "run_cli"]


class RayStartedInProcess(AssertionError):
    """A command run by :func:`run_cli` tried to start or join Ray (its address in the message)."""


@dataclass
class CliResult:
    """What :func:`run_cli` returns, named as :class:`subprocess.CompletedProcess` names it: ``returncode`` (the
    exit code: :func:`aerodaas.cli.main`'s return value, a ``SystemExit``'s code, or 1 for an exception that
    escaped, whose traceback is in ``stderr`` as the interpreter would print it), ``stdout`` and ``stderr``."""

    args: list[str]
    returncode: int
    stdout: str
    stderr: str


def _exit_code(code) -> int:
    """The process exit code of ``SystemExit(code)`` (Python docs, ``sys.exit``)."""
    if code is None:
        return 0
    return code if isinstance(code, int) else 1


def _foreign_modules(before: set[str]) -> list[str]:
    """The modules imported since ``before`` that are neither installed nor this checkout's own."""
    out = []
    for name in set(sys.modules) - before:
        f = getattr(sys.modules.get(name), "__file__", None)
        if name.startswith("aerodaas_app_") or (f and not str(Path(f).resolve()).startswith(_KEPT_ROOTS)):
            out.append(name)
    return out


@contextlib.contextmanager
def _framework_state():
    """Put the plug-in registry and the process state back as they were (see the module)."""
    from aerodaas.plugins.registry import REGISTRY
    from aerodaas.process.state import PROCESS

    with REGISTRY.lock:
        entries = {kind: dict(table) for kind, table in REGISTRY.entries.items()}
        flags = (REGISTRY.builtins_loaded, REGISTRY.entry_points_loaded, set(REGISTRY.by_value))
    stop, ray_conn = copy.copy(PROCESS.stop), copy.copy(PROCESS.ray)
    stop.signals = list(stop.signals)
    links = dict(PROCESS.mavlink_links.by_key)
    try:
        yield
    finally:
        with REGISTRY.lock:
            REGISTRY.entries.clear()
            REGISTRY.entries.update(entries)
            REGISTRY.builtins_loaded, REGISTRY.entry_points_loaded, REGISTRY.by_value = flags
        PROCESS.stop, PROCESS.ray = stop, ray_conn
        PROCESS.mavlink_links.by_key.clear()
        PROCESS.mavlink_links.by_key.update(links)


@contextlib.contextmanager
def _no_ray(calls: list, shared: bool = False):
    """``init_ray``/``start_ray_early`` record their address in ``calls`` and raise; ``shutdown_ray`` is a no-op.
    ``shared``: the command may use the Ray session this process is connected to, so only ``init_ray`` (a start or
    join of another) is refused and Ray's own functions are left alone."""
    from aerodaas.runtime import ray_start

    if shared:
        ray = sys.modules.get("ray")
        if ray is None or not ray.is_initialized():
            raise RuntimeError("run_cli(shared_ray=True) needs the shared Ray session: request ray_session")

    def refuse(address=None, dashboard=False):
        calls.append(address)
        raise RayStartedInProcess(f"a command run in-process tried to start or join Ray (address {address!r})")

    patched = [(ray_start, n, getattr(ray_start, n)) for n in ("init_ray", "start_ray_early", "shutdown_ray")]
    ray_start.init_ray = refuse
    if not shared:
        ray_start.start_ray_early = refuse
    ray_start.shutdown_ray = lambda: None
    ray = sys.modules.get("ray")
    if ray is not None and not shared:  # the worker's shared session may be up: the command sees none, as a new process
        patched += [(ray, n, getattr(ray, n)) for n in ("init", "is_initialized")]
        ray.init = lambda address=None, **kw: refuse(address)
        ray.is_initialized = lambda: False
    try:
        yield
    finally:
        for owner, n, f in patched:
            setattr(owner, n, f)


@contextlib.contextmanager
def _process_context(cwd: Path | str | None, env: dict | None):
    """Environment, working folder, ``sys.path``/``argv``, signal handlers and root log handlers, put back."""
    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    saved_path, saved_argv = list(sys.path), list(sys.argv)
    saved_signals = {s: signal.getsignal(s) for s in _SIGNALS}
    root = logging.getLogger()
    saved_handlers, saved_level = list(root.handlers), root.level
    try:
        if env is not None:
            os.environ.clear()
            os.environ.update(env)
            # what the interpreter of a subprocess would put on its path
            sys.path[:0] = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
        if cwd is not None:
            os.chdir(cwd)
        yield
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        sys.path[:], sys.argv[:] = saved_path, saved_argv
        for s, h in saved_signals.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        root.handlers[:] = saved_handlers
        root.setLevel(saved_level)


def run_cli(*args: str, cwd: Path | str | None = None, env: dict | None = None, shared_ray: bool = False) -> CliResult:
    """``aerodaas ARGS`` run in this process by :func:`aerodaas.cli.main` in ``cwd`` (default: the current folder)
    with the environment ``env`` (default: this process's; its ``PYTHONPATH`` goes first on ``sys.path``), its
    stdout and stderr captured. Raises :class:`RayStartedInProcess` when the command tried to start or join Ray
    (after putting everything back).

    ``shared_ray``: an ``aerodaas run`` that flies, on the session the tests of this pytest worker share (the caller
    requests the ``ray_session`` fixture, which then checks that the run left no actor behind). Only where isolation
    allows: the session's workers started with the environment of the test process, so a run whose actors need
    an environment variable or ``PYTHONPATH`` entry of ``env`` keeps a subprocess."""
    from aerodaas import cli

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    calls: list = []
    modules = set(sys.modules)
    ray_was_up = "ray" in sys.modules and sys.modules["ray"].is_initialized()
    if shared_ray and env is not None and env.get("PYTHONPATH") != os.environ.get("PYTHONPATH"):
        raise ValueError("run_cli(shared_ray=True): the shared session's workers never see this PYTHONPATH")
    try:
        with _process_context(cwd, env), _framework_state(), _no_ray(calls, shared_ray), \
                contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            sys.argv[:] = ["aerodaas", *argv]
            try:
                code = cli.main(argv)
            except SystemExit as e:  # argparse's usage errors (exit 2), an explicit sys.exit
                code = _exit_code(e.code)
                if e.code is not None and not isinstance(e.code, int):
                    print(e.code, file=sys.stderr)
            except Exception:  # noqa: BLE001 - as the interpreter ends a process: the traceback on stderr, exit 1
                traceback.print_exc()
                code = 1
    finally:
        for name in _foreign_modules(modules):
            sys.modules.pop(name, None)
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized() != ray_was_up:
        calls.append("ray.is_initialized() changed")
    if calls:
        raise RayStartedInProcess(f"`aerodaas {' '.join(argv)}` tried to start or join Ray ({calls}); stderr: "
                                  f"{err.getvalue()[-1500:]}")
    return CliResult(argv, int(code), out.getvalue(), err.getvalue())
