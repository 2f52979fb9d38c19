"""Whose exception is it? ``aerodaas run`` tells an exception raised by the application's own code (a bug in the
app: exit 1, printed with the app's traceback) from bad input AeroDaaS refused (a ConfigError, or a
FileNotFoundError / ValueError / KeyError raised by AeroDaaS's own code about something the app gave it: exit 2,
one line naming it). The innermost frame of the traceback that is not a library's (the standard library,
site-packages, Ray) decides: AeroDaaS's packages, or the application's code."""
from __future__ import annotations

import os
import sys
import sysconfig
import traceback
from types import TracebackType

__all__ = ["raised_by_app", "app_traceback", "report", "INPUT_ERRORS"]

#: exception types that, raised by AeroDaaS's own code, mean bad input (exit 2)
INPUT_ERRORS = (FileNotFoundError, ValueError, KeyError)


def _ours() -> tuple[str, ...]:
    roots = {os.path.dirname(os.path.dirname(os.path.abspath(__file__)))}  # aerodaas/ (this file: aerodaas/runtime/)
    for name in ("aerodaas.actors", "aerodaas.schedulers", "aerodaas.clusters"):
        mod = sys.modules.get(name)
        if mod is not None and getattr(mod, "__file__", None):
            roots.add(os.path.dirname(os.path.abspath(mod.__file__)))
    return tuple(r + os.sep for r in roots)


def _libraries() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    return tuple(os.path.abspath(paths[k]) + os.sep for k in ("stdlib", "platstdlib", "purelib", "platlib")
                 if paths.get(k))


def _frames(tb: TracebackType | None) -> list[str]:
    out = []
    while tb is not None:
        out.append(os.path.abspath(tb.tb_frame.f_code.co_filename) if not
                   tb.tb_frame.f_code.co_filename.startswith("<") else tb.tb_frame.f_code.co_filename)
        tb = tb.tb_next
    return out


def raised_by_app(e: BaseException) -> bool:
    """True when the innermost non-library frame of ``e``'s traceback is the application's code (not AeroDaaS's
    packages ``aerodaas``, ``aerodaas.actors``, ``aerodaas.schedulers``, ``aerodaas.clusters``). An exception without a traceback is not
    the app's."""
    ours, libs = _ours(), _libraries()
    for f in reversed(_frames(e.__traceback__)):
        if f.startswith("<"):
            continue
        if f.startswith(ours):
            return False
        if f.startswith(libs):
            continue
        return True
    return False


def app_traceback(e: BaseException, app: str) -> str:
    """``e``'s traceback from the application's first frame on (the ``aerodaas run`` and runpy frames above it
    left out)."""
    app = os.path.abspath(app)
    tb = e.__traceback__
    t = tb
    while t is not None and os.path.abspath(t.tb_frame.f_code.co_filename) != app:
        t = t.tb_next
    return "".join(traceback.format_exception(type(e), e, t if t is not None else tb))


def report(e: Exception, app: str, prog: str) -> int:
    """Print ``e`` for the command ``prog`` (``aerodaas run``) and return its exit code: 2 with one line for bad
    input AeroDaaS refused (:data:`INPUT_ERRORS` raised by its own code), 1 with the traceback (from the app's first
    frame) for the app's own exception (or, raised in AeroDaaS and not an input error, a bug of ours)."""
    if isinstance(e, INPUT_ERRORS) and not raised_by_app(e):
        print(f"{prog}: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    who = f"the application {app!r}" if raised_by_app(e) else "AeroDaaS (a bug: please report it)"
    print(f"{prog}: {who} raised {type(e).__name__}: {e}\n{app_traceback(e, app)}".rstrip(), file=sys.stderr)
    return 1
