"""The options of one run (``aerodaas run``'s flags, or a test's): a value handed to the runner
(:func:`aerodaas.runtime.driver.run_application` / :func:`~aerodaas.runtime.driver.run_mission`); nothing reads
them from a global."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from aerodaas.protocol.actor_classes import ActorClasses, ActorClassesSource

__all__ = ["RunOptions", "actor_classes", "check_actor_classes"]


@dataclass
class RunOptions:
    """Options of one run; None: the environment file's value. ``speedup``: simulated seconds per wall second;
    ``timeout``: wall-clock limit of the mission, s; ``record``: the MCAP file to write; ``address``: the Ray
    cluster to join (None: a local Ray); ``env_path``: an environment file used instead of the one the application
    names (applies while the application is loaded)."""

    record: str | None = None
    speedup: float | None = None
    lockstep: bool | None = None
    #: ``--recorder-hold``: over ``simulation.recorder_hold_s`` (wall s)
    recorder_hold_s: float | None = None
    timeout: float | None = None
    address: str | None = None
    env_path: str | None = None
    progress: bool = True
    hitl: bool | None = None  # force the human-in-the-loop API on/off (default: environment.json hitl.enabled)
    hitl_port: int | None = None
    live: str | None = None  # serve the run to Foxglove over WebSocket on this HOST:PORT (aerodaas.liveview.server)
    #: the live view's TLS files and token (:class:`aerodaas.clusters.tls.ServeAccess`; ``aerodaas run`` builds it
    #: with :func:`aerodaas.liveview.server.live_access`); None: plain, no token (loopback)
    live_access: Any = None
    #: ``--tls-cert`` / ``--tls-key``: the certificate and key of the HITL API (over ``hitl.tls_*``) and the live view
    tls_cert: str | None = None
    tls_key: str | None = None
    #: ``--insecure``: the HITL API and the live view may serve in clear text off loopback (the summary says so)
    insecure: bool = False
    #: a local Ray also starts its dashboard on 127.0.0.1 (``aerodaas run --dashboard``: it serves
    #: ``ray list actors`` and the actors view; off by default: it adds seconds to the start and on a loaded machine
    #: can fail to start, which then costs a retry without it)
    dashboard: bool = False
    #: the run's id in its actors' names (``aerodaas/<run id>/...``); None: a random one per run
    run_id: str | None = None
    #: --overwrite: --record may replace an existing file that is not an AeroDaaS recording
    overwrite: bool = False
    #: the run's actor classes and component handle classes (the runtime imports no actor module): the entry point
    #: that starts the run sets them — ``start_mission()`` and ``aerodaas run`` the built-in source
    #: :data:`aerodaas.actors.builtin.source.BUILTIN` (loaded once the input passed its checks) when None; a test may hand
    #: the record itself (:data:`aerodaas.actors.builtin.catalogue.BUILTIN_ACTORS`); the runner refuses None (ValueError,
    #: before Ray)
    actors: ActorClasses | ActorClassesSource | None = None


def check_actor_classes(opts: RunOptions) -> None:
    """Raises ValueError (before Ray starts, without importing any actor module) when the entry point handed no
    actor classes (``opts.actors`` None) or something that is neither a record nor a source of them."""
    if opts.actors is None:
        raise ValueError("RunOptions.actors: None; the code that starts a run hands the runtime its actor classes "
                         "(RunOptions(actors=aerodaas.actors.builtin.source.BUILTIN), as start_mission() and "
                         "`aerodaas run` do)")
    if not isinstance(opts.actors, (ActorClasses, ActorClassesSource)):
        raise ValueError(f"RunOptions.actors: {type(opts.actors).__name__}; expected an ActorClasses record or an "
                         "ActorClassesSource (aerodaas.protocol.actor_classes)")


def actor_classes(opts: RunOptions) -> ActorClasses:
    """``opts.actors`` as the record: a source (:class:`~aerodaas.protocol.actor_classes.ActorClassesSource`) is
    loaded, which imports its actor modules. Raises ValueError when the entry point handed none, and what loading
    the source raises."""
    check_actor_classes(opts)
    return opts.actors.load() if isinstance(opts.actors, ActorClassesSource) else opts.actors
