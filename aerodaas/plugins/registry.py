"""One registry for every extension point of AeroDaaS: vehicle backends, sensor types, analytics, trajectory
schedulers and analytics (edge/cloud placement) schedulers.

A plug-in is a class that declares what it is (class attributes, see :class:`PluginDeclaration`): its ``kind``
(one of :data:`KINDS`), its name (the word ``environment.json`` or the application uses), its ``Config`` (a
pydantic model of its settings) and the messages it ``produces`` and ``consumes``. It reaches the registry in one
of three ways, and the registry remembers which (its *origin*):

* ``entry point DIST`` — an installed distribution declares it in its metadata under the group of its kind
  (:data:`ENTRY_POINT_GROUPS`: ``aerodaas.backends``, ``aerodaas.sensors``, ``aerodaas.analytics``,
  ``aerodaas.trajectory_schedulers``, ``aerodaas.analytics_schedulers``), the packaging convention read with
  :func:`importlib.metadata.entry_points` (Python Packaging User Guide, "Entry points specification"). The
  built-ins are declared this way too, by this package's own ``pyproject.toml``: their origin is
  ``entry point aerodaas (built-in)`` (:data:`BUILTIN_ORIGIN`, :attr:`PluginEntry.builtin`); they are read before
  any other distribution's, so a built-in's name is taken from the start;
* ``decorator in FILE`` — the application (or any module) applied :func:`register` / :func:`plugin` (or one of the
  kind-specific decorators such as :func:`aerodaas.schedulers.analytics_base.register_analytics_scheduler`);
* ``import path MODULE:CLASS`` — ``environment.json`` names the class itself where a name is accepted
  (``"backend": "my_pkg.wind:GustyBackend"``, a sensor's ``"type"``, ``analytics_scheduler.name``).

An entry point is only read from the metadata when the registry is first asked; its module is imported when the
plug-in is used (:meth:`PluginEntry.load`), so that listing the simulator backend never imports pymavlink.

What travels to the actors is the class object itself, inside the actor's spec: Ray serialises it with
cloudpickle, by value when it was defined in the application (``__main__``) or in a module reached by an import
path outside any installed distribution (:func:`by_value_modules`), by reference (module and name, imported on the
worker) when it comes from an installed package. Never only its name: a name means nothing in another process.

An unknown name raises :class:`UnknownPlugin` (a ValueError) naming the kind, the name and every available plug-in
with its origin; configuration validation turns it into a ConfigError before Ray starts (``aerodaas run``: exit 2).
"""
from __future__ import annotations

import difflib
import functools
import importlib
from importlib.metadata import PackageNotFoundError, distribution, entry_points, packages_distributions
import inspect
import sys
import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from aerodaas.model.ids import check_plugin_name

from pydantic import BaseModel

__all__ = ["KINDS", "ENTRY_POINT_GROUPS", "BUILTIN_DIST", "BUILTIN_ORIGIN", "MissingBuiltins", "PluginEntry", "UnknownPlugin", "InvalidPlugin", "declaration_error",
           "register", "plugin", "get", "class_origin", "names_with_flag", "KIND_BASES", "kind_base", "base_error", "resolve", "entries", "names", "describe_all", "adopt", "by_value_modules",
           "PluginRegistry", "REGISTRY",
           "plugin_package_paths", "plugin_name", "is_import_path", "installed_top_level_packages"]

#: the extension points, and the ``importlib.metadata`` entry-point group of each
ENTRY_POINT_GROUPS: dict[str, str] = {
    "backend": "aerodaas.backends",
    "sensor": "aerodaas.sensors",
    "analytics": "aerodaas.analytics",
    "trajectory_scheduler": "aerodaas.trajectory_schedulers",
    "analytics_scheduler": "aerodaas.analytics_schedulers",
    "frame_source": "aerodaas.frame_sources",
}
KINDS: tuple[str, ...] = tuple(ENTRY_POINT_GROUPS)
#: the distribution whose entry points are the built-ins (this package, ``[project] name`` in pyproject.toml)
BUILTIN_DIST = "aerodaas"
#: the origin of a built-in plug-in: an entry point of :data:`BUILTIN_DIST`
BUILTIN_ORIGIN = f"entry point {BUILTIN_DIST} (built-in)"
#: the class every plug-in of a kind subclasses (``"module:Class"``, imported when a plug-in is resolved): the
#: framework constructs and calls a plug-in as one of these (a backend as ``Backend(cfg)``, a trajectory scheduler
#: as ``Scheduler(env)``), so a class that is not one is refused before it is instantiated
KIND_BASES: dict[str, str] = {
    "backend": "aerodaas.backends.base:VehicleBackend",
    "sensor": "aerodaas.plugins.sensor:SensorPlugin",
    "analytics": "aerodaas.analytics.base:Analytics",
    "trajectory_scheduler": "aerodaas.schedulers.base:TrajectoryScheduler",
    "analytics_scheduler": "aerodaas.schedulers.analytics_base:AnalyticsScheduler",
    "frame_source": "aerodaas.plugins.frames:FrameSource",
}


class UnknownPlugin(ValueError):
    """No plug-in of ``kind`` is called ``name``. The message lists what is available and where each came from."""

    def __init__(self, kind: str, name: str, available: list["PluginEntry"], why: str = "") -> None:
        self.kind, self.name = kind, name

        avail = ", ".join(f"{e.name!r} ({e.origin})" for e in available) or "none"
        close = difflib.get_close_matches(name, [e.name for e in available], n=1)
        extra = f": {why}" if why else (f" (did you mean {close[0]!r}?)" if close else "")
        super().__init__(f"unknown {kind.replace('_', ' ')} {name!r}{extra}; available: {avail}")


class MissingBuiltins(RuntimeError):
    """The installed metadata of :data:`BUILTIN_DIST` declares none of its entry points: the package is imported
    from a folder that was never installed, or pyproject.toml's entry points were edited without re-installing.
    The message says how to install it (README, "Install")."""

    def __init__(self) -> None:
        super().__init__(f"the built-in plug-ins (sim, camera, ObjectDetector, ...) are declared as entry points of "
                         f"the {BUILTIN_DIST!r} distribution, and its installed metadata declares none: install the "
                         f"package (pip install -e . in its folder, README 'Install'), or re-install it after "
                         f"editing the entry points in pyproject.toml")


class InvalidPlugin(UnknownPlugin):
    """A plug-in class was found but its declaration cannot be used (its ``Config`` is not a pydantic model): the
    message names the kind, the name, the class and what is wrong. An UnknownPlugin, so that every check of a
    configured name reports it with its field."""

    def __init__(self, kind: str, name: str, message: str) -> None:
        ValueError.__init__(self, message)
        self.kind, self.name = kind, name


def declaration_error(cls: Any, kind: str, name: str) -> str | None:
    """What is wrong with the declaration of plug-in class ``cls`` registered as ``name`` of ``kind``, None when
    nothing: ``Config``, when declared (not None), must be a pydantic BaseModel subclass — the framework validates the
    plug-in's settings with ``Config.model_validate`` when the environment is loaded, and anything else failed there
    as a raw AttributeError. A class that is itself a pydantic model keeps pydantic's own ``Config``."""
    cfg = getattr(cls, "Config", None)
    if cfg is None or (isinstance(cfg, type) and issubclass(cfg, BaseModel)):
        return None
    if isinstance(cls, type) and issubclass(cls, BaseModel):
        return None
    what = f"the class {cfg.__module__}.{cfg.__qualname__}, which is not a pydantic BaseModel" \
        if isinstance(cfg, type) else f"{type(cfg).__name__} {cfg!r:.80}"
    base = " (subclass aerodaas.plugins.SensorPluginConfig)" if kind == "sensor" else ""
    where = f"{getattr(cls, '__module__', '?')}.{getattr(cls, '__qualname__', cls)}"
    return (f"{kind.replace('_', ' ')} plug-in {name!r} (class {where}): Config must be a pydantic BaseModel "
            f"subclass, the model of its settings{base}, or None; got {what}")


def kind_base(kind: str) -> type:
    """The class every plug-in of ``kind`` subclasses (:data:`KIND_BASES`)."""
    mod, _, attr = KIND_BASES[kind].partition(":")
    return getattr(importlib.import_module(mod), attr)


def base_error(cls: Any, kind: str, name: str) -> str | None:
    """What is wrong with ``cls`` as plug-in ``name`` of ``kind`` when it is not a subclass of the kind's base
    (:func:`kind_base`), None when it is: ``"subprocess:Popen"`` as a trajectory scheduler was accepted and then
    constructed as ``Popen(env)``."""
    base = kind_base(kind)
    if isinstance(cls, type) and issubclass(cls, base):
        return None
    what = f"class {cls.__module__}.{cls.__qualname__}" if isinstance(cls, type) else f"{type(cls).__name__} {cls!r:.80}"
    return (f"{kind.replace('_', ' ')} plug-in {name!r} ({what}) is not a subclass of {base.__module__}."
            f"{base.__qualname__}, the base of every {kind.replace('_', ' ')} plug-in")


def _check_declaration(cls: Any, kind: str, name: str) -> None:
    """Raise :class:`InvalidPlugin` for what :func:`declaration_error` finds."""
    why = declaration_error(cls, kind, name)
    if why:
        raise InvalidPlugin(kind, name, why)


def _check_plugin_class(cls: Any, kind: str, name: str) -> None:
    """Raise :class:`InvalidPlugin` for a class that is not of its kind's base (:func:`base_error`) or whose
    declaration cannot be used (:func:`declaration_error`): what a resolved plug-in must pass before it is used."""
    why = base_error(cls, kind, name)
    if why:
        raise InvalidPlugin(kind, name, why)
    _check_declaration(cls, kind, name)


@dataclass
class PluginEntry:
    """One registered plug-in: ``kind``, ``name``, ``origin`` (see the module docstring), ``target``
    (``"module:attr"``, where the class lives), ``cls`` once loaded (imports are deferred until first use, so
    that listing the simulator backend never imports pymavlink) and ``dist``, the distribution whose entry point
    declared it (None for a decorator, an import path or a class adopted from a spec)."""

    kind: str
    name: str
    origin: str
    target: str
    cls: type | None = field(default=None, repr=False)
    error: str | None = None  # why loading failed (an entry point whose module does not import)
    dist: str | None = None

    @property
    def builtin(self) -> bool:
        """Whether this package declares it (an entry point of :data:`BUILTIN_DIST`): known in every process
        that imports aerodaas, so never carried in an actor's spec."""
        return self.dist == BUILTIN_DIST

    def load(self) -> type:
        """The plug-in class (imported on first use). Raises ImportError/AttributeError naming the target, also for
        a module that calls ``sys.exit`` while it is imported (it ended runs with exit 0 and no flight)."""
        if self.cls is None:
            mod, _, attr = self.target.partition(":")
            try:
                obj: Any = importlib.import_module(mod)
            except SystemExit as e:
                raise ImportError(f"module {mod!r} called sys.exit({e.code!r}) while being imported") from None
            for part in attr.split("."):
                obj = getattr(obj, part)
            self.cls = obj
        return self.cls

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description: kind, name, origin, class, config fields, produces/consumes."""
        out: dict[str, Any] = {"kind": self.kind, "name": self.name, "origin": self.origin, "class": self.target}
        cls = self.cls
        if cls is None and self.dist is not None:
            try:
                cls = self.load()
            except Exception as e:  # noqa: BLE001 - listed with its error, never fatal for a listing
                self.error = f"{type(e).__name__}: {e}"
        error = self.error or (declaration_error(cls, self.kind, self.name) if cls is not None else None)
        if error:
            out["error"] = error
        if cls is not None:
            cfg = getattr(cls, "Config", None)
            if isinstance(cfg, type) and hasattr(cfg, "model_fields"):
                out["config"] = sorted(cfg.model_fields)
            for k in ("produces", "consumes"):
                v = getattr(cls, k, None)
                if v:
                    out[k] = [getattr(x, "__name__", str(x)) for x in v]
        return out


def _empty_tables() -> dict[str, dict[str, PluginEntry]]:
    return {k: {} for k in KINDS}


@dataclass
class PluginRegistry:
    """The plug-ins known to this process: ``entries`` (kind -> name -> :class:`PluginEntry`), whether this
    package's own entry points (``builtins_loaded``) and every other distribution's (``entry_points_loaded``) were
    read from the metadata, and ``by_value`` (modules reached by an import path that no installed distribution
    provides, :func:`by_value_modules`); ``lock`` guards them (the registry is read from an actor's threads).
    The module's functions (:func:`register`, :func:`resolve`, :func:`entries`, ...) act on :data:`REGISTRY`."""

    entries: dict[str, dict[str, PluginEntry]] = field(default_factory=_empty_tables)
    builtins_loaded: bool = False
    entry_points_loaded: bool = False
    by_value: set[str] = field(default_factory=set)
    lock: threading.RLock = field(default_factory=threading.RLock, repr=False)


#: the one plug-in registry of this process, and the only module-level mutable state of the framework besides the
#: process's own state — signal handling, Ray connection, shared MAVLink links (:data:`aerodaas.process.state.PROCESS`;
#: tests/architecture/test_module_state.py): a plug-in class registered in a module is known to the whole process, as Python's
#: own import system knows a module (sys.modules)
REGISTRY = PluginRegistry()

def _check_kind(kind: str) -> None:
    if kind not in ENTRY_POINT_GROUPS:
        raise ValueError(f"unknown plug-in kind {kind!r}; kinds: {list(KINDS)}")


def plugin_name(cls: type, kind: str | None = None) -> str:
    """The name ``cls`` registers under: ``plugin_name`` if set, else ``kind`` for a vehicle backend (the
    ``backend`` value of ``environment.json``), else ``name``, else the class name."""
    explicit = getattr(cls, "plugin_name", None)
    if explicit:
        return str(explicit)
    kind = kind or getattr(cls, "plugin_kind", None)
    if kind == "trajectory_scheduler":  # their ``name`` says how they order ("ordered"), shared by subclasses
        return cls.__name__
    if kind == "backend" and isinstance(getattr(cls, "kind", None), str) and cls.kind:
        return cls.kind
    n = getattr(cls, "name", None)
    return n if isinstance(n, str) and n else cls.__name__


def _origin_of(cls: type) -> str:
    mod = getattr(cls, "__module__", "") or ""
    try:
        where = inspect.getsourcefile(cls) or getattr(sys.modules.get(mod), "__file__", None) or mod
    except (TypeError, OSError):  # a built-in module, or a class defined in `python -c` (no source)
        where = getattr(sys.modules.get(mod), "__file__", None) or mod
    return f"decorator in {where}"


def register(cls: type, kind: str | None = None, name: str | None = None, *, origin: str | None = None,
             replaces: bool | None = None) -> type:
    """Register ``cls`` as a plug-in of ``kind`` (default its ``plugin_kind``) under ``name`` (default
    :func:`plugin_name`). Returns ``cls`` (usable as a decorator body). Raises ValueError for an unknown kind, a
    name outside the plug-in name grammar (:func:`aerodaas.model.ids.check_plugin_name`), :class:`InvalidPlugin` (a
    ValueError) for a ``Config`` that is not a pydantic model (:func:`declaration_error`), or a name already taken
    by another class — a built-in's too (``sim``, ``camera``, ``ObjectDetector``...: a user backend called ``sim``
    replaced the simulator silently) — unless the registration says it replaces it: ``replaces=True``
    or the class attribute ``plugin_replaces = True``. Raises :class:`MissingBuiltins` when the package's own
    entry points are not installed. A class registering itself under the name and target of an entry point (its
    module imported by the entry point) keeps the entry point's origin."""
    kind = kind or getattr(cls, "plugin_kind", None)
    if kind is None:
        raise ValueError(f"{cls.__name__}: a plug-in class declares its kind (plugin_kind = one of {list(KINDS)})")
    _check_kind(kind)
    name = name or plugin_name(cls, kind)
    if not name:
        raise ValueError(f"{cls.__name__}: a {kind} plug-in needs a non-empty name")

    check_plugin_name(name, f"{cls.__name__}: {kind.replace('_', ' ')} plug-in name")
    _check_declaration(cls, kind, name)
    origin = origin or _origin_of(cls)
    target = f"{cls.__module__}:{cls.__qualname__}"
    if replaces is None:
        replaces = getattr(cls, "plugin_replaces", False) is True
    _load_builtins()  # a built-in's name is taken from the start (metadata only: nothing imported)
    with REGISTRY.lock:
        old = REGISTRY.entries[kind].get(name)
        if old is not None and old.target != target and not replaces:
            raise ValueError(f"{kind.replace('_', ' ')} name {name!r} is already taken by {old.target} ({old.origin}); "
                             f"choose another name, or say that it replaces it (replaces=True / plugin_replaces = True)")
        dist = None
        if old is not None and old.target == target and old.dist is not None:
            origin, dist = old.origin, old.dist  # the entry point's module registered itself on import
        REGISTRY.entries[kind][name] = PluginEntry(kind, name, origin, target, cls, dist=dist)
    return cls


def plugin(kind: str, name: str | None = None, *, replaces: bool | None = None) -> Callable[[type], type]:
    """Class decorator: ``@plugin("sensor")`` registers the class as a plug-in of ``kind`` (see :func:`register`;
    ``replaces=True`` to take a name already taken)."""
    _check_kind(kind)

    def deco(cls: type) -> type:
        return register(cls, kind, name, replaces=replaces)

    return deco


def _distribution_entry_points(builtin: bool) -> list[tuple[str, str, str, str]]:
    """``(kind, name, target, dist)`` of every installed entry point in the aerodaas groups, of :data:`BUILTIN_DIST`
    only (``builtin``) or of every other distribution; read from the metadata, nothing imported. The built-ins
    from this package's own metadata alone (under 1 ms), the others from one scan of every installed
    distribution (``entry_points(group=...)`` once per group scanned them five times: 224 ms against 37 ms at
    load 26 on the 2-core machine), since every Ray worker that resolves ``sim`` reads the built-ins; each
    distribution's name read once (it parses the distribution's METADATA: this package's 36 entry points cost 36
    parses, 0.12 s of the scan's 0.18 s of CPU at load 40)."""
    kinds = {g: k for k, g in ENTRY_POINT_GROUPS.items()}
    if builtin:
        try:
            own = distribution(BUILTIN_DIST).entry_points
        except PackageNotFoundError:
            return []
        return [(kinds[ep.group], ep.name, ep.value, BUILTIN_DIST) for ep in own if ep.group in kinds]
    out = []
    installed = entry_points()
    dist_names: dict[int, str] = {}  # a Distribution's ``name`` parses its METADATA file each time it is read
    for group, kind in kinds.items():
        for ep in installed.select(group=group):
            d = getattr(ep, "dist", None)
            if id(d) not in dist_names:  # the entry points of one distribution share its object
                dist_names[id(d)] = getattr(d, "name", None) or "?"
            dist = dist_names[id(d)]
            if dist != BUILTIN_DIST:
                out.append((kind, ep.name, ep.value, dist))
    return out


def _load_builtins() -> None:
    """Register the entry points of this package (the built-ins), before any other distribution's: their names are
    taken from the start. Raises :class:`MissingBuiltins` when the installed metadata declares none."""
    if REGISTRY.builtins_loaded:
        return
    with REGISTRY.lock:
        if REGISTRY.builtins_loaded:
            return
        found = _distribution_entry_points(builtin=True)
        if not found:
            raise MissingBuiltins()
        for kind, name, target, dist in found:
            REGISTRY.entries[kind].setdefault(name, PluginEntry(kind, name, BUILTIN_ORIGIN, target, dist=dist))
        REGISTRY.builtins_loaded = True


def _load_entry_points() -> None:
    """Register the entry points of every other installed distribution (after the built-ins). A name already taken
    (a built-in's, or a class the application registered first) keeps its plug-in."""
    _load_builtins()
    if REGISTRY.entry_points_loaded:
        return
    with REGISTRY.lock:
        if REGISTRY.entry_points_loaded:
            return
        REGISTRY.entry_points_loaded = True
        for kind, name, target, dist in _distribution_entry_points(builtin=False):
            REGISTRY.entries[kind].setdefault(name, PluginEntry(kind, name, f"entry point {dist}", target, dist=dist))


def is_import_path(name: str) -> bool:
    """Whether ``name`` has the form ``"module.path:ClassName"``."""
    mod, sep, attr = name.partition(":")
    return bool(sep and mod and attr) and all(p.isidentifier() for p in mod.split(".") + attr.split("."))


def _from_import_path(kind: str, name: str) -> PluginEntry:
    mod = name.partition(":")[0]
    entry = PluginEntry(kind, name, f"import path {name}", name)
    try:
        cls = entry.load()
    except Exception as e:  # noqa: BLE001 - reported as an unknown plug-in with the cause
        raise UnknownPlugin(kind, name, entries(kind), f"cannot import it ({type(e).__name__}: {e})") from None
    if not isinstance(cls, type):
        raise UnknownPlugin(kind, name, entries(kind), f"{name} is a {type(cls).__name__}, not a class")
    declared = getattr(cls, "plugin_kind", kind)
    if declared != kind:
        raise UnknownPlugin(kind, name, entries(kind), f"{name} declares plugin_kind {declared!r}")
    _check_plugin_class(cls, kind, name)
    if not _installed(sys.modules[mod]):
        REGISTRY.by_value.add(mod)
    with REGISTRY.lock:
        REGISTRY.entries[kind][name] = entry
    return entry


def _installed(module: Any) -> bool:
    """Whether ``module`` comes from an installed distribution (site-packages, or an editable install that
    ``importlib.metadata`` knows): a worker can then import it; else it must travel by value."""
    path = getattr(module, "__file__", None) or ""
    if "site-packages" in path or "dist-packages" in path:
        return True
    try:
        return module.__name__.split(".")[0] in installed_top_level_packages()
    except Exception:  # noqa: BLE001
        return False


@functools.cache
def installed_top_level_packages() -> frozenset[str]:
    """The top-level import names of the installed distributions (:func:`importlib.metadata.packages_distributions`,
    which reads every distribution's metadata and file list: about 0.1 CPU-s on a quiet 2-core machine with this
    project's test rig installed). Read once per process: a distribution installed or removed later is not seen
    until the process restarts (or ``installed_top_level_packages.cache_clear()``); like the entry points, which are
    also read once."""
    return frozenset(packages_distributions())


def resolve(kind: str, name: str) -> PluginEntry:
    """The registry entry of plug-in ``name`` of ``kind``: registered (decorator), an installed entry point (a
    built-in is one), or — when ``name`` is ``"module.path:ClassName"`` — that class. Raises
    :class:`UnknownPlugin`, :class:`MissingBuiltins`."""
    _check_kind(kind)
    with REGISTRY.lock:
        e = REGISTRY.entries[kind].get(name)
    if e is None and not REGISTRY.builtins_loaded:  # a built-in (``sim``): this package's metadata alone, under 1 ms;
        _load_builtins()  # the scan of every installed distribution (30+ ms of CPU per process) only for the others
        e = REGISTRY.entries[kind].get(name)
    if e is None:
        _load_entry_points()
        e = REGISTRY.entries[kind].get(name)
    if e is None and is_import_path(name):
        e = _from_import_path(kind, name)
    if e is None:
        raise UnknownPlugin(kind, name, entries(kind))
    return e


def get(kind: str, name: str) -> type:
    """The class of plug-in ``name`` of ``kind`` (see :func:`resolve`). Raises :class:`UnknownPlugin`, also when
    the class cannot be imported (the message names the target and the import error), and :class:`InvalidPlugin`
    (an UnknownPlugin) for a class that does not subclass its kind's base (:func:`base_error`) or whose
    declaration cannot be used (:func:`declaration_error`)."""
    e = resolve(kind, name)
    try:
        cls = e.load()
    except Exception as ex:  # noqa: BLE001
        raise UnknownPlugin(kind, name, entries(kind),
                            f"{e.target} ({e.origin}) does not import: {type(ex).__name__}: {ex}") from None
    _check_plugin_class(cls, kind, name)  # an entry point's class, or a Config replaced after registration
    return cls


def entries(kind: str | None = None) -> list[PluginEntry]:
    """Every registered plug-in (of ``kind``), built-ins and installed entry points included, in kind order."""
    _load_entry_points()
    kinds: Iterable[str] = [kind] if kind else KINDS
    with REGISTRY.lock:
        return [e for k in kinds for e in REGISTRY.entries[k].values()]


def names(kind: str) -> list[str]:
    """The names of every plug-in of ``kind``."""
    return [e.name for e in entries(kind)]


def class_origin(kind: str, cls: type) -> tuple[str, str]:
    """``(name, origin)`` of the class ``cls`` used as a plug-in of ``kind`` (an object the application built, such
    as its trajectory scheduler), as ``aerodaas plugins`` lists it: the registered entry whose class (or
    ``module:qualname`` target) is ``cls``; a class that was never registered is named by :func:`plugin_name` and
    its origin is :data:`BUILTIN_ORIGIN` when it lives in the ``aerodaas`` package, else ``unregistered class in FILE``.
    Raises ValueError for an unknown kind."""
    _check_kind(kind)
    target = f"{cls.__module__}:{cls.__qualname__}"
    for e in entries(kind):
        if e.cls is cls or e.target == target:
            return e.name, e.origin
    if (cls.__module__ or "").split(".")[0] == BUILTIN_DIST:  # a class of this package's own
        return plugin_name(cls, kind), BUILTIN_ORIGIN
    return plugin_name(cls, kind), _origin_of(cls).replace("decorator in", "unregistered class in", 1)


def names_with_flag(kind: str, flag: str) -> list[str]:
    """Names of the registered plug-ins of ``kind`` whose class declares the class attribute ``flag`` true (a
    backend's ``provides_camera``, a frame source's ``environment_ok``), for error messages that list the choices;
    a plug-in whose module does not import is left out. Raises ValueError for an unknown kind."""
    out = []
    for e in entries(kind):
        try:
            if getattr(e.load(), flag, False):
                out.append(e.name)
        except Exception:  # noqa: BLE001 - a plug-in that does not import offers nothing
            continue
    return out


def describe_all(kind: str | None = None) -> list[dict[str, Any]]:
    """:meth:`PluginEntry.describe` of every plug-in (``aerodaas plugins --json``)."""
    return [e.describe() for e in entries(kind)]


def adopt(carried: Iterable[tuple[str, str, type, str]]) -> None:
    """Register plug-in classes that travelled to this process in an actor's spec, ``(kind, name, class, origin)``,
    under the name and origin the driver resolved them with (a class defined in the application, or reached by an
    import path, is known here only this way)."""
    with REGISTRY.lock:
        for kind, name, cls, origin in carried:
            REGISTRY.entries[kind][name] = PluginEntry(kind, name, origin, f"{cls.__module__}:{cls.__qualname__}", cls)


def plugin_package_paths() -> list[str]:
    """The folder (or single file) of every installed plug-in package: the top-level module of each entry point in
    the aerodaas groups, found without importing it. The driver ships them to a cluster it attaches to as Ray's
    job-level ``runtime_env={"py_modules": [...]}`` (Ray docs, "Environment Dependencies"), so that nodes where
    the package is not installed import it too. ``aerodaas`` itself is never shipped."""
    out: list[str] = []
    for group in ENTRY_POINT_GROUPS.values():
        for ep in entry_points(group=group):
            top = ep.value.split(":")[0].split(".")[0].strip()
            if not top or top == "aerodaas":
                continue
            try:
                spec = importlib.util.find_spec(top)
            except (ImportError, ValueError):
                continue
            if spec is None:
                continue
            locs = list(spec.submodule_search_locations or [])
            path = locs[0] if locs else spec.origin
            if path and path not in out:
                out.append(path)
    return out


def by_value_modules() -> list[str]:
    """Modules reached by an import path that no installed distribution provides: their classes must travel to
    the actors by value (``ray.cloudpickle.register_pickle_by_value``, called by the driver before actors start)."""
    return sorted(REGISTRY.by_value)
