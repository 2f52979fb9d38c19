"""Ray actor plumbing shared by the actor modules: :class:`LazyActorClass` (``ray.remote`` applied on first use,
so importing an actor module does not import Ray) and :func:`where` (the process, node and node labels an actor
runs on)."""
from __future__ import annotations

import os
import sys
from typing import Any

__all__ = ["LazyActorClass", "where"]


def where() -> dict:
    """``pid`` and, inside a Ray worker, the ``node_id`` and node ``labels`` of this process."""
    out: dict[str, Any] = {"pid": os.getpid(), "node_id": None, "labels": {}}
    ray = sys.modules.get("ray")  # not imported here: outside Ray there is nothing to ask (and it takes seconds)
    try:
        if ray is not None and ray.is_initialized():
            ctx = ray.get_runtime_context()
            out["node_id"] = ctx.get_node_id()
            out["labels"] = dict(ctx.get_node_labels())
    except Exception:  # informational only
        pass
    return out


def _ray_remote(cls, **options):
    import ray  # lazy: heavy ray

    return ray.remote(**options)(cls)


class LazyActorClass:
    """``ray.remote`` applied on first use, so importing this module does not import Ray."""

    def __init__(self, cls, **options) -> None:
        self._cls, self._options, self._actor = cls, options, None

    def _get(self):
        if self._actor is None:
            self._actor = _ray_remote(self._cls, **self._options)
        return self._actor

    def options(self, **kw):
        return self._get().options(**kw)

    def remote(self, *a, **kw):
        return self._get().remote(*a, **kw)
