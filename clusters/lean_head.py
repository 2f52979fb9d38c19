"""The head processes of a run's own local Ray when the run has no dashboard: the GCS only, without the
autoscaler monitor and without the dashboard's API server.

``ray.init(address="local")`` starts a head node through Ray's private ``Node`` (``ray/_private/node.py``,
``Node.start_head_processes``, Ray 2.60): the GCS, then the autoscaler monitor (``Node.start_monitor``, nothing in
``ray.init``'s keywords turns it off: ``RayParams.no_monitor`` is not passed through), then the dashboard's API
server (``Node.start_api_server``), which ``ray.init`` waits for until it has written its address to the GCS. With
``include_dashboard=False`` that server loads Ray's usage-stats module only, with no front-end and no state API
(``ray list actors`` and ``ray.util.state`` answer from the full dashboard alone, ``aerodaas run --dashboard``):
it serves a run nothing, yet its start (importing aiohttp and the dashboard's framework, about 0.9 s of CPU on the
2-core machine kind) lies on the path to ``ray.init``'s return, and the monitor's (0.5 s) competes with it and with
the raylet for the cores. A single local node has nothing to autoscale.

:func:`without_monitor_and_api_server` makes the ``Node`` of a ``ray.init`` started inside it skip both; the raylet
and its agents, the log monitor (worker output to the console) and the reaper start as before. It changes Ray's
classes in this process only while the block runs and restores them on leaving; it is used only for a Ray this
driver starts itself, never for a cluster it joins or attaches to (there ``ray.init`` starts no node). A Ray
without these methods is left alone (the block then changes nothing), and so is every head while
``AERODAAS_LEAN_HEAD`` is ``0``.
"""
from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["LEFT_OUT", "without_monitor_and_api_server"]

#: the methods of ``ray._private.node.Node`` that start what a run without a dashboard leaves out
LEFT_OUT = ("start_monitor", "start_api_server")

_lock = threading.Lock()


def _skip(_node: Any, *_args: Any, **_kwargs: Any) -> None:
    """Stands in for a left-out start method: starts nothing (``Node.all_processes`` then has no entry for it,
    which ``Node.kill_all_processes`` and ``ray.shutdown`` accept, as for a worker node)."""
    return None


@contextlib.contextmanager
def without_monitor_and_api_server() -> Iterator[bool]:
    """Within the block, a head node that ``ray.init`` starts in this process starts neither the autoscaler monitor
    nor the dashboard's API server (see the module). Yields True when in effect, False when this Ray's ``Node`` has
    not both of :data:`LEFT_OUT` or ``AERODAAS_LEAN_HEAD`` is ``0`` (nothing is changed then). Not re-entrant across
    threads: a second block waits."""
    if os.environ.get("AERODAAS_LEAN_HEAD", "").strip() == "0":
        yield False
        return
    try:
        from ray._private.node import Node  # lazy: heavy ray
    except ImportError:
        yield False
        return
    if not all(callable(getattr(Node, name, None)) for name in LEFT_OUT):
        yield False
        return
    with _lock:
        saved = {name: Node.__dict__[name] for name in LEFT_OUT if name in Node.__dict__}
        for name in LEFT_OUT:
            setattr(Node, name, _skip)
        try:
            yield True
        finally:
            for name in LEFT_OUT:
                if name in saved:
                    setattr(Node, name, saved[name])
                else:
                    delattr(Node, name)
