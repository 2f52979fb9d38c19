"""A loopback-only local Ray: every server of a Ray started on this machine listens on 127.0.0.1 only.

Used by the driver's own local Ray (:func:`aerodaas.runtime.ray_start.init_ray`), the persistent cluster of
``aerodaas up`` (:mod:`aerodaas.clusters.persistent`) and the local test cluster (:mod:`aerodaas.clusters.local`).
"""
from __future__ import annotations

import os
from typing import Callable

__all__ = ["RAY_LOCAL_ONLY_ENV", "loopback_only"]

#: the environment variable with which Ray takes loopback as the node's address (ray/_private/ray_constants.py
#: ``ENABLE_RAY_CLUSTER``, read by ``services.get_node_ip_address``; Ray's own default on macOS and Windows)
RAY_LOCAL_ONLY_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def loopback_only() -> Callable[[], None]:
    """Make the local Ray about to start a loopback-only one: node address 127.0.0.1, so the GCS, raylet, object
    manager and every worker's gRPC server listen on 127.0.0.1 only (since Ray binds its servers to the node IP,
    ray-project/ray#55484, #59852), not on the machine's network address. ``ray.init(_node_ip_address=
    "127.0.0.1")`` does not do it (``resolve_ip_for_localhost`` turns loopback back into the network address).
    The variable reaches Ray's processes through their environment; the driver's copy of the constant is set too
    (Ray may already be imported). Returns the function that undoes both once Ray has started (its processes keep
    the variable; a later ``ray.init(address=...)`` of this process must see the machine's address again). A
    cluster joined with ``--address`` is never touched."""
    from ray._private import ray_constants  # lazy: heavy ray

    before_env, before_const = os.environ.get(RAY_LOCAL_ONLY_ENV), ray_constants.ENABLE_RAY_CLUSTER
    os.environ[RAY_LOCAL_ONLY_ENV] = "0"
    ray_constants.ENABLE_RAY_CLUSTER = False

    def restore() -> None:
        ray_constants.ENABLE_RAY_CLUSTER = before_const
        if before_env is None:
            os.environ.pop(RAY_LOCAL_ONLY_ENV, None)
        else:
            os.environ[RAY_LOCAL_ONLY_ENV] = before_env

    return restore
