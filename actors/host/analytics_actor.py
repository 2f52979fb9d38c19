"""AnalyticsActor and DispatcherActor: where analytics run when they are not colocated with a drone.

* :class:`AnalyticsActor` — one replica of one deployed analytics (``analytics.deploy(compute, replicas=n)``),
  named ``aerodaas/<run>/analytics/<compute>/<name>#<k>[/r<i>]`` and placed with ``label_selector`` on the compute
  resource's tier and labels. Frames arrive as ObjectRefs (``ray.put`` once by the drone actor, mapped zero-copy
  from the node's object store) or JPEG bytes across tiers; results (detections, navigation) go back as small
  messages. It keeps per-drone state in the analytics (each drone's items always reach the same replica).
* :class:`DispatcherActor` — the analytics scheduler of one edge compute resource (DEMS, GEMS, ... per edge
  device, as in the reference scheduler), named ``aerodaas/<run>/dispatcher/<compute>``: it runs the analytics
  placed per frame on its edge executor and sends the rest to the cloud executors on ``tier=cloud`` nodes.

Both are restartable (``max_restarts``): a restarted actor rebuilds itself from its spec; frames that were in
flight are counted as failed by their senders and the analytics' navigation resumes with the next frame.
"""
from __future__ import annotations

import ray

from aerodaas.actors.host.base import ActorBase


@ray.remote(num_cpus=0, max_concurrency=32)
class AnalyticsActor(ActorBase):
    """One replica of one deployed analytics (see the module docstring)."""


@ray.remote(num_cpus=0, max_concurrency=32)
class DispatcherActor(ActorBase):
    """The analytics scheduler of one edge compute resource (see the module docstring)."""
