"""The state a process has once, whatever runs in it: a driver's signal handling (the stop signals of ``aerodaas
run``) and its Ray connection (the local Ray it started, or the cluster of ``aerodaas up`` it attached to), and the
MAVLink connections that the robots of one process (a driver, or a drone actor packing several drones) share.

All three are process-wide by nature — ``signal.signal`` installs a handler for the whole process, ``ray.init``
connects the whole process (Python docs, "signal — Set handlers for asynchronous events": handlers always run in
the main thread; Ray docs, ``ray.init``: one connection per driver process), and a UDP port is bound by one socket,
which every robot of the process naming that endpoint must then read — so they live in one documented object,
:data:`PROCESS`, instead of module-level lists and dicts. Nothing else of the framework keeps
module-level mutable state outside the plug-in registry (:data:`aerodaas.plugins.registry.REGISTRY`); the test
``tests/architecture/test_module_state.py`` checks it.
"""
from __future__ import annotations

import subprocess
import threading
from dataclasses import dataclass, field
from typing import Any

__all__ = ["StopState", "EarlyStart", "RayConnection", "SharedConnections", "ProcessState", "PROCESS"]


@dataclass
class StopState:
    """The stop signals of this process (SIGINT/SIGTERM as ``aerodaas run`` handles them).

    ``signals``: the signal numbers received, in order; ``raise_ok``: whether raising KeyboardInterrupt in the main
    thread is safe now — while the application is built and while a mission runs, yes; while actors are set up or
    torn down, no (an exception inside a Ray call there can leave the core worker half shut down and abort the
    process: exit 134 instead of 143, the recording unfinished), the stop is then taken at the next safe point,
    which ends the mission as ``interrupted`` with the recording finished; ``in_mission``: True while
    :func:`aerodaas.runtime.driver.run_mission` runs (a stop signal then ends the mission; after it, a signal that
    comes once a mission's summary was printed does not change the run's exit code)."""

    signals: list[int] = field(default_factory=list)
    raise_ok: bool = True
    in_mission: bool = False

    def reset(self) -> None:
        """Forget the signals received (a new ``aerodaas run`` in this process)."""
        self.signals.clear()

    def record(self, signum: int) -> None:
        """Remember signal ``signum`` without raising: the run stops at its next safe point, and a further mission
        of the application does not start."""
        self.signals.append(int(signum))

    def request(self, signum: int) -> None:
        """Record signal ``signum`` and raise KeyboardInterrupt when :attr:`raise_ok` (called by the CLI's
        SIGINT/SIGTERM handler, in the main thread)."""
        self.record(signum)
        if self.raise_ok:
            raise KeyboardInterrupt(f"signal {signum}")

    def stopped(self) -> bool:
        """Whether a stop signal was received (a method: the supervisor polls it)."""
        return bool(self.signals)


@dataclass
class EarlyStart:
    """The background start of Ray (:func:`aerodaas.runtime.ray_start.start_ray_early`): the ``address`` it
    starts or joins (None: a local Ray), ``ready`` once it ended, ``error`` what it raised (None: none)."""

    address: str | None
    ready: threading.Event = field(default_factory=threading.Event)
    error: BaseException | None = None


@dataclass
class RayConnection:
    """What this process did with Ray: ``local`` (started a Ray of its own, shut down by
    :func:`aerodaas.runtime.ray_start.shutdown_ray`), ``attached_up`` (joined the persistent local cluster of
    ``aerodaas up``, placed as a local Ray is), ``early`` (the background start in progress or done, None when
    none) and ``reaper`` (the process reaper it started with its local Ray, :func:`aerodaas.clusters.reaper.
    ensure_started`; None: none started by this object)."""

    local: bool = False
    attached_up: bool = False
    early: EarlyStart | None = None
    reaper: subprocess.Popen | None = None


@dataclass
class SharedConnections:
    """The connections of this process that several robots share, by endpoint key (for MAVLink:
    :meth:`aerodaas.config.MavlinkConfig.link_key`, e.g. ``udpin:0.0.0.0:14550``) → the open link
    (:class:`aerodaas.backends.mavlink.shared_link.SharedLink`, which opens, hands out and closes them). Read and
    changed only while holding ``lock``."""

    by_key: dict[str, Any] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)


@dataclass
class ProcessState:
    """The process-wide state: a driver's :class:`StopState` and :class:`RayConnection`, and the MAVLink links the
    process's robots share (:class:`SharedConnections`)."""

    stop: StopState = field(default_factory=StopState)
    ray: RayConnection = field(default_factory=RayConnection)
    mavlink_links: SharedConnections = field(default_factory=SharedConnections)


#: the process-wide state of this process (signal handling, Ray connection, shared MAVLink links; see the module
#: docstring)
PROCESS = ProcessState()
