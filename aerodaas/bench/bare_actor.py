"""An idle Ray actor created as a drone actor is (``@ray.remote(num_cpus=0, max_concurrency=32)``, in the run's Ray
with its workers' set-up): what one more Ray actor costs a node before any of the framework's code runs in it.
``aerodaas bench fleet --profile`` keeps one beside the fleet and measures it over the drone actor's window
(:class:`~aerodaas.bench.fleet_profile.ActorProfiler`), so the framework's share per drone is read beside the floor
that any one-Ray-actor-per-drone layout pays. This module imports only Ray, so the actor holds nothing more."""
from __future__ import annotations

import os

import ray


@ray.remote(num_cpus=0, max_concurrency=32)
class BareActor:
    """No state and no threads of its own: only Ray's worker; :meth:`pid` is its one call."""

    def pid(self) -> int:
        """The actor's process id."""
        return os.getpid()
