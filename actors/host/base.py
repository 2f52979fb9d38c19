"""What every actor of a run shares: a :class:`~aerodaas.actors.data.plane.DataPlane` (its components and the routes between actors), built
from the plan's spec by :class:`~aerodaas.actors.host.assembly.ActorAssembly`, and the calls the driver makes on it.

An actor gets its whole spec and wiring (routes, locations, peers by Ray actor name) in its constructor, so when
Ray restarts it (``max_restarts``) it rebuilds itself: the constructor sees
``ray.get_runtime_context().was_current_actor_reconstructed`` and sets up again at once, and its peers reach it
again under the same name. The first start is set up by the driver (:meth:`ActorBase.setup`) so that a failure
there (an unreachable vehicle) reaches the driver as that call's error.
"""
from __future__ import annotations

import os
import sys
from typing import Any, Callable
import warnings

import ray
from ray import cloudpickle

from aerodaas.actors.data.channel import ChannelServer, channel_address
from aerodaas.protocol.messages import Delivery
from aerodaas.protocol.specs import ActorSpec
from aerodaas.protocol.startup_probe import probe

from aerodaas.actors.data.plane import DataPlane, Settled


def restarted_actor() -> bool:
    """True in the constructor of an actor that Ray restarted (``max_restarts``)."""
    with warnings.catch_warnings():  # Ray's own property reads its deprecated ``actor_id`` inside
        warnings.simplefilter("ignore")
        return bool(ray.get_runtime_context().was_current_actor_reconstructed)


def self_name() -> str:
    """This actor's Ray name."""
    return ray.get_runtime_context().get_actor_name() or ""


def _recorder_name(name: str) -> str:
    """``aerodaas/<run>/drone/d1`` -> ``aerodaas/<run>/recorder``."""
    parts = name.split("/")
    return "/".join(parts[:2] + ["recorder"])


class ActorBase:
    """Plain base of the run's Ray actors (see the module docstring). Its part of the plan
    (:class:`~aerodaas.protocol.specs.ActorSpec`) and its wiring (``{"routes", "location", "tiers", "peers"}``) are read
    from the run's recorder actor, which keeps every actor's, so that a restarted actor gets them the same way."""

    def __init__(self, actor_id: str, tier: str, workers: int | None = None,
                 switch_interval_s: float | None = 0.0005) -> None:
        probe(f"actor_init:{actor_id}")  # the constructor runs: the worker is up and this module imported
        if switch_interval_s:
            # the default GIL switch interval (5 ms) would let a busy Python thread delay a frame that is ready
            # to move on by up to 5 ms; the actors are latency-bound, not throughput-bound
            sys.setswitchinterval(switch_interval_s)

        # the run's recorder actor keeps every actor's spec (see aerodaas.runtime.supervise.start_actors)
        spec_b, wiring_b = ray.get(ray.get_actor(_recorder_name(self_name())).spec_of.remote(actor_id), timeout=60)
        spec: ActorSpec = cloudpickle.loads(spec_b)
        wiring: dict = cloudpickle.loads(wiring_b)
        self.spec, self.wiring = spec, wiring
        self.plane = DataPlane(actor_id, tier, int(spec.epoch_ns), workers, restart_hold_s=spec.restart_hold_s)
        self.plane.connect(wiring.get("routes", {}), wiring.get("location", {}), wiring.get("tiers", {}),
                          wiring.get("peers", {}))
        self.channel = None
        key = wiring.get("channel_key")
        if key:  # same-node channels (aerodaas.actors.data.channel): use the peers', serve ours (below)
            self.plane.channel_key = key
        self.runtime: Any = None
        self.restarts = 0
        if restarted_actor():
            self.restarts = 1
            self.on_restart()
        if key:
            # served once a restarted actor is set up again: its senders reconnect as soon as the address is
            # served, and a frame delivered before its component exists was an error ("KeyError: 'always_car#1'",
            # twice in a full-suite run); until then their sends fail and are counted, as the Ray calls queued by
            # Ray behind this constructor would wait
            self.channel = self._serve_channel(actor_id, key)

    def _serve_channel(self, actor_id: str, key: bytes) -> Any:
        """This actor's :class:`~aerodaas.actors.data.channel.ChannelServer`, or None when its address cannot be served (peers then
        reach this actor through Ray calls)."""
        try:
            return ChannelServer(channel_address(key, actor_id), key, self.plane.deliver,
                                 on_error=self.plane.report_error)
        except OSError as e:
            print(f"aerodaas: actor {actor_id!r}: no same-node channel ({e}); peers use Ray calls", file=sys.stderr)
            return None

    def on_restart(self) -> None:
        """Called in the constructor of a restarted actor: set up again from the stored spec."""
        self.setup()

    def setup(self) -> dict:
        """Create this actor's components (drones connect to their vehicles here). Returns :meth:`describe`."""
        from aerodaas.actors.host.assembly import ActorAssembly  # lazy: heavy pydantic, pymap3d, shapely

        if self.runtime is None:
            self.runtime = ActorAssembly(self.plane, self.spec)
            probe(f"actor_setup:{self.plane.actor_id}")  # its components built (drones connected)
            self.plane.watch_gc()
        return self.describe()

    def describe(self) -> dict:
        out = self.runtime.describe() if self.runtime is not None else {"host": self.plane.actor_id}
        return {**out, "pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id(),
                "restarts": self.restarts}

    def ping(self) -> int:
        """The actor's process id (a cheap liveness probe)."""
        return os.getpid()

    pid = ping

    def deliver(self, d: Delivery) -> list:
        """A message from another actor for one of this actor's components (see :meth:`aerodaas.actors.data.plane.DataPlane.deliver`:
        a lock-step delivery returns once its cascade here is done)."""
        return self.plane.deliver(d)

    def call(self, cid: str, method: Callable, *args: Any, **kwargs: Any) -> Any:
        """Call ``method`` — a public method of the component's class, the function itself (e.g.
        ``DroneComponent.status``, see :mod:`aerodaas.actors.builtin.handles`), never its name — on component ``cid``
        with ``args``; a subclass's override runs. Raises TypeError when ``method`` is not a public method of the
        component's class (or a base of it), KeyError for an unknown component, RuntimeError before setup."""
        if self.runtime is None:
            raise RuntimeError(f"actor {self.plane.actor_id!r} is not set up yet (component {cid!r})")
        comp = self.runtime.lookup(cid)
        name = getattr(method, "__name__", "")
        if not callable(method) or name.startswith("_") or not any(
                vars(k).get(name) is method for k in type(comp).__mro__):
            raise TypeError(f"component {cid!r} ({type(comp).__name__}): {method!r} is not one of its public "
                            f"methods")
        return getattr(comp, name)(*args, **kwargs)

    def settle(self, timeout_s: float) -> Settled:
        """Wait (at most ``timeout_s`` seconds) until nothing of this actor is in flight (see
        :meth:`aerodaas.actors.data.plane.DataPlane.settle`); called on every actor once the drones stopped, before the counts."""
        return self.plane.settle(timeout_s)

    def drain(self) -> bool:
        """Finish the work in flight once the drones are done (the analytics scheduler's tasks)."""
        return self.runtime.drain() if self.runtime else False

    def stats(self) -> dict:
        return self.runtime.stats() if self.runtime else {}

    def close(self) -> dict:
        if self.channel is not None:
            self.channel.close()
        return self.runtime.close() if self.runtime else {}

    def recording_report(self) -> dict:
        return self.runtime.recording_report() if self.runtime else {}
