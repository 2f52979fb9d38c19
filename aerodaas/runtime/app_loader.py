"""Loading an application: an app file (``apps/farm_survey.py``) becomes an :class:`Application` value — its
environment, robots, analytics, trajectory schedulers and the point where its mission starts — without Ray and
without flying. ``aerodaas run``, ``aerodaas plan`` and ``aerodaas plugins --app`` all load with :func:`load_app`;
the runner (:func:`aerodaas.runtime.driver.run_application`) takes the value and flies it.

While a file loads, its ``start_mission()`` (robot or fleet) only marks the mission's start in the value: the
file's execution stops there (:class:`MissionMarked`), the application's graph is checked
(:func:`aerodaas.runtime.preflight.validate_graph`) and nothing flies. An application whose code goes on after the
mission (it prints the result, flies a second mission) is loaded again after the flight with the results so far
(:func:`load_app` ``flown``): each ``start_mission()`` already flown returns its result, the next one marks the next
mission.

The file runs as the module :func:`app_module_name` (``aerodaas_app_<file stem>``) under every loader, so what it
defines has one name however it is loaded — a plug-in sensor's schema ``aerodaas_app_my_app.Level``, its registry
origin ``decorator in FILE`` — and its classes travel to the actors by value (cloudpickle), where that module is
not importable.
"""
from __future__ import annotations

import ast
import importlib.util
import io
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from aerodaas.runtime.options import RunOptions

__all__ = ["Application", "AppGraph", "MissionStart", "MissionMarked", "load_app", "app_module_name",
           "env_path_override", "mark_mission"]


@dataclass(frozen=True)
class AppGraph:
    """The application's checked dataflow graph for the robots of its mission: robot id -> its analytics in
    topological order (:func:`aerodaas.runtime.dataflow.collect_graph`), robot id -> its trajectory scheduler (a fork
    of a shared one), and id(analytics) -> the analytics the analytics scheduler places per frame."""

    analytics: Mapping[str, tuple]
    schedulers: Mapping[str, Any]
    scheduled: Mapping[int, Any]


@dataclass(frozen=True)
class MissionStart:
    """Where the application starts its mission: the environment, the robots that fly (in order), the
    ``timeout`` it asked for (wall seconds; None: none) and the line of the app file that called
    ``start_mission()`` (None: not called from the file itself)."""

    env: Any
    robots: tuple
    timeout: float | None
    line: int | None = None
    top_level: bool = False  # called from the file's top level (not from inside one of its functions)


@dataclass(frozen=True)
class Application:
    """A loaded application: its file, the module it ran as, its mission start (None: the file never called
    ``start_mission()``; it may only register plug-ins) with the checked graph, and ``continues``: code of the file
    runs after that mission (see the module docstring). Nothing of it has started Ray or flown."""

    path: str
    module: str
    mission: MissionStart | None = None
    graph: AppGraph | None = None
    continues: bool = False
    #: missions of the file already flown before this one (a load with ``flown``)
    index: int = 0

    @property
    def robots(self) -> tuple:
        """The robots of the mission (empty without one)."""
        return self.mission.robots if self.mission else ()

    def plan(self, options: Any = None, *, run_id: str | None = None, epoch_ns: int = 0):
        """The run's typed dataflow graph and its placement (:class:`aerodaas.runtime.dataflow.RunPlan`) under
        ``options`` (a :class:`~aerodaas.runtime.options.RunOptions`; default: none). Starts nothing. Raises
        ValueError when the application has no mission."""
        from aerodaas.runtime.dataflow import build_plan  # lazy: heavy numpy, pydantic, pymap3d, shapely
        from aerodaas.runtime.preflight import simulation_for  # lazy: heavy numpy, pydantic, pymap3d, shapely

        if self.mission is None or self.graph is None:
            raise ValueError(f"{self.path}: the application never called start_mission()")
        opts = options or RunOptions()
        env, robots = self.mission.env, list(self.mission.robots)
        return build_plan(env, robots, dict(self.graph.analytics), dict(self.graph.schedulers),
                          simulation_for(env, robots, opts), record=opts.record, live=opts.live,
                          scheduled=dict(self.graph.scheduled), epoch_ns=epoch_ns, run_id=run_id)


class MissionMarked(BaseException):
    """Raised out of the application's ``start_mission()`` while it loads (a BaseException, so that the app's own
    ``except Exception`` does not swallow it): ``start`` is the mission it marks, ``graph`` its checked graph."""

    def __init__(self, start: MissionStart, graph: AppGraph) -> None:
        super().__init__("mission start marked")
        self.start, self.graph = start, graph


@dataclass
class _Load:
    """The state of one load in progress, held in the namespace of the app module being run (under
    :data:`_LOAD_NAME`, for the load only: :func:`_load_in_progress` finds it on the stack), never a global of the
    run."""

    path: str
    env_path: str | None
    flown: tuple = ()
    marks: int = 0
    stdout: Any = field(default=None, repr=False)


#: the name under which the app module being loaded holds its :class:`_Load` in its own namespace (set by
#: :func:`load_app` before the module runs, removed when it stops)
_LOAD_NAME = "__aerodaas_load__"


def _load_in_progress() -> _Load | None:
    """The load in progress, seen from the calling code: the innermost frame on this thread's stack that runs code
    of an app module being loaded holds it in its globals (:data:`_LOAD_NAME`). None outside a load: after it,
    or in a thread whose stack holds no code of the app being loaded."""
    f = sys._getframe(1)
    while f is not None:
        load = f.f_globals.get(_LOAD_NAME)
        if isinstance(load, _Load):
            return load
        f = f.f_back
    return None


def app_module_name(path: str | os.PathLike) -> str:
    """The module name an app file runs as under every loader: ``aerodaas_app_`` + its file stem with every
    character that cannot be in an identifier replaced by ``_`` (``apps/farm_survey.py``:
    ``aerodaas_app_farm_survey``). Prefixed so that an app called ``json.py`` does not replace a library."""
    return "aerodaas_app_" + re.sub(r"\W", "_", Path(path).stem)


def env_path_override() -> str | None:
    """The environment file given to the load in progress (``aerodaas run --env``), used by
    :class:`aerodaas.app.api.Environment` instead of the one the application names; None outside a load."""
    load = _load_in_progress()
    return load.env_path if load is not None else None


_NOT_LOADING = object()


def _caller_in_app(path: str) -> tuple[int | None, bool]:
    """The line of the innermost frame of the app file ``path`` on the stack, and whether it is the file's top
    level."""
    f = sys._getframe(2)
    while f is not None:
        if os.path.abspath(f.f_code.co_filename) == path:
            return f.f_lineno, f.f_code.co_name == "<module>"
        f = f.f_back
    return None, False


def mark_mission(env: Any, robots: list, timeout: float | None) -> Any:
    """Called by ``start_mission()``: outside a load, returns a sentinel (the caller flies). While a file loads,
    returns the result of this mission when it already flew (``flown``), else checks the graph and raises
    :class:`MissionMarked` (nothing flies). Raises what the checks raise (ConfigError, ValueError naming the
    field)."""
    load = _load_in_progress()
    if load is None:
        return _NOT_LOADING
    index = load.marks
    load.marks += 1
    if index < len(load.flown):
        if load.marks == len(load.flown) and load.stdout is not None:  # the replay of what ran is over: show output
            sys.stdout, load.stdout = load.stdout, None
        return load.flown[index]
    from aerodaas.runtime.preflight import validate_graph  # lazy: heavy numpy, pydantic, pymap3d, shapely

    graphs, scheds, scheduled = validate_graph(env, robots)
    line, top = _caller_in_app(load.path)
    graph = AppGraph(MappingProxyType({rid: tuple(v) for rid, v in graphs.items()}), MappingProxyType(dict(scheds)),
                     MappingProxyType(dict(scheduled)))
    raise MissionMarked(MissionStart(env, tuple(robots), timeout, line, top), graph)


def is_sentinel(value: Any) -> bool:
    """True for :func:`mark_mission`'s "not loading" answer."""
    return value is _NOT_LOADING


def _code_after(path: str, start: MissionStart) -> bool:
    """Whether the app file runs code after the ``start_mission()`` of ``start``: always when it was called from
    inside a function of the file or from outside it, else when a top-level statement follows its statement."""
    if start.line is None or not start.top_level:
        return True
    body = ast.parse(Path(path).read_text(), filename=path).body
    return any(stmt.lineno > start.line for stmt in body
               if not (stmt.lineno <= start.line <= (stmt.end_lineno or stmt.lineno)))


def _exit_error(path: str, e: SystemExit):
    """The ConfigError for an application that called ``sys.exit`` while it loaded (nothing would fly)."""
    from aerodaas.config import ConfigError  # lazy: heavy numpy, pydantic, pymap3d, shapely

    tb = e.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = f" in {tb.tb_frame.f_code.co_filename} line {tb.tb_lineno}" if tb is not None else ""
    return ConfigError(f"{path}: sys.exit({e.code!r}) was called{where} while the application was being built, "
                       f"before its first start_mission(); nothing flew")


def _ran_app_code(e: BaseException, path: str) -> bool:
    """Whether a frame of the app file ``path`` is in ``e``'s traceback (else ``e`` was raised compiling the file,
    before any of its code ran)."""
    tb = e.__traceback__
    while tb is not None:
        if os.path.abspath(tb.tb_frame.f_code.co_filename) == path:
            return True
        tb = tb.tb_next
    return False


def _syntax_error(path: str, e: SyntaxError):
    """The ConfigError for an app file that is not valid Python (``e`` raised compiling it): the file, the line,
    Python's reason and the line itself with a caret under the column. Bad input, not a bug of AeroDaaS (it was
    reported as one, exit 1)."""
    from aerodaas.config import ConfigError  # lazy: heavy numpy, pydantic, pymap3d, shapely

    text = (e.text or "").rstrip("\n")
    shown = text.lstrip()
    caret = ""
    if shown and e.offset:
        col = max(0, min(len(text), e.offset - 1) - (len(text) - len(shown)))
        caret = f"\n    {' ' * col}^"
    where = f", line {e.lineno}" if e.lineno else ""
    return ConfigError(f"application file {path!r}{where}: not valid Python: {type(e).__name__}: {e.msg}"
                       + (f"\n    {shown}{caret}" if shown else ""))


def load_app(path: str | os.PathLike, env_path: str | None = None, *, flown: tuple = ()) -> Application:
    """Load the app file ``path`` into an :class:`Application` (see the module docstring): run it as the module
    :func:`app_module_name` (its folder first on ``sys.path``) until its first ``start_mission()`` not in
    ``flown`` (the results of its missions already flown, returned by those calls; the file's output up to there
    is not shown again), or to its end. ``env_path``: an environment file used instead of the one it names.
    Starts no Ray, flies nothing. Raises FileNotFoundError for a missing file, ConfigError for a file that is not
    valid Python (naming the file and line) or an app that calls ``sys.exit`` while loading, and whatever the
    application's code or the checks raise."""
    p = os.path.abspath(path)
    if not os.path.isfile(p):
        raise FileNotFoundError(f"application file {str(path)!r} not found")
    name = app_module_name(p)
    spec = importlib.util.spec_from_file_location(name, p)
    if spec is None or spec.loader is None:
        raise ValueError(f"application file {str(path)!r}: not a Python file")
    folder = os.path.dirname(p)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # its classes know their module: dataclasses, pydantic and the registry need it
    load = _Load(p, env_path, tuple(flown))
    if flown:
        load.stdout, sys.stdout = sys.stdout, io.StringIO()
    module.__dict__[_LOAD_NAME] = load  # the load's state, where the app's own code runs (_load_in_progress)
    try:
        spec.loader.exec_module(module)
    except MissionMarked as m:
        return Application(p, name, m.start, m.graph, _code_after(p, m.start), len(flown))
    except SystemExit as e:
        raise _exit_error(str(path), e) from None
    except SyntaxError as e:
        if _ran_app_code(e, p):
            raise  # a module the app imports, or code it compiles itself: the app's own error
        raise _syntax_error(str(path), e) from None
    finally:
        module.__dict__.pop(_LOAD_NAME, None)
        if load.stdout is not None:
            sys.stdout = load.stdout
    return Application(p, name, index=len(flown))
