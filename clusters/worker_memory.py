"""The C heap of the Ray processes AeroDaaS starts on this machine: at most two glibc malloc arenas per process.

glibc gives every thread that allocates its own malloc arena, up to eight per core; a drone actor runs a dozen
threads (Ray's threaded-actor executor, the data plane's pools, the camera and control loops), and each arena
keeps 1-3 MB of freed memory. ``MALLOC_ARENA_MAX=2`` (glibc ``mallopt(M_ARENA_MAX)``, read when a process starts,
so it must be in the environment of the node processes before they are launched, which their workers inherit)
caps that. Measured with ``aerodaas bench fleet --drones 1 --drones 20 --duration 20`` on the 2-core CI machine
kind: 88-91 MB of PSS per extra drone actor without it, 77 MB with it, missed control ticks 0.07-0.25 % and
0.02 %. A value the user already set is kept; ``AERODAAS_MALLOC_ARENA_MAX=0`` leaves glibc's default.

The Python heap: when a Ray process first deserialises anything, its serialisation context applies Ray's add-ons
(``ray.util.serialization_addons.apply``, Ray 2.60), and each imports the library it serves: pyarrow for Ray Data's
Arrow reducers (``ray/_private/arrow_serialization.py``; +30 MB private per process on CPython 3.11), Pydantic's
v1 compatibility package for FastAPI's ``ModelField`` (``ray/_common/pydantic_compat.py``; ``pydantic.v1``, 0.17 s
of CPU in a drone actor) and Starlette with anyio for Serve's app state. No actor of a run uses any of them.
:func:`lean_worker_imports` names :func:`worker_setup` as the workers' setup hook (Ray's
``worker_process_setup_hook``, passed through the environment the node processes and their workers inherit, like
``MALLOC_ARENA_MAX``); it runs in each worker before its serialisation context exists and lets each add-on register
only when its library is already imported (:data:`ADDONS`). An actor that imports one of them later still sends its
objects through Ray (pickled by cloudpickle without Ray's reducer). A run's driver does the same for itself
(:func:`addons_only_when_imported`, called before it starts or joins Ray): its first actor creation otherwise
imported them on the path to the first frame. ``AERODAAS_LEAN_WORKERS=0`` turns both off.

OpenBLAS (numpy's BLAS) starts a pool of one thread per core when numpy is imported, each with its own stack and,
once it computes, its own work buffer. An actor's numpy work is poses and small matrices, which OpenBLAS runs on the
calling thread anyway; the pool only holds memory and threads in every worker, more on a node with more cores.
:func:`worker_setup` sets ``OPENBLAS_NUM_THREADS=1`` (read by OpenBLAS when numpy loads it, which in a worker comes
after the hook: a bare Ray worker does not import numpy) unless the user set it or numpy is already imported;
``AERODAAS_LEAN_WORKERS=0`` leaves OpenBLAS's default too.
"""
from __future__ import annotations

import importlib
import os
import sys

__all__ = ["ADDONS", "ARENAS", "BLAS_THREADS", "SETUP_HOOK", "SETUP_HOOK_ENV", "addons_only_when_imported",
           "lean_worker_imports", "limit_malloc_arenas", "one_blas_thread", "worker_setup"]

#: glibc malloc arenas per process of the Ray nodes AeroDaaS starts
ARENAS = 2
#: OpenBLAS's threads in each Ray worker AeroDaaS sets up (:func:`worker_setup`)
BLAS_THREADS = 1
#: the environment variable a Ray worker reads its setup hook from (``ray._private.ray_constants.
#: WORKER_PROCESS_SETUP_HOOK_ENV_VAR``; ``ray/_private/workers/default_worker.py`` runs the hook before the main loop)
SETUP_HOOK_ENV = "__RAY_WORKER_PROCESS_SETUP_HOOK_ENV_VAR"
#: the hook: an import path, loaded by Ray with ``load_class``
SETUP_HOOK = "aerodaas.clusters.worker_memory.worker_setup"
#: Ray's serialisation add-ons registered only in a process that already imported their library: (the module of the
#: register function, its name, the library's module). ``serialization_addons.apply`` looks each up at call time
ADDONS = (("ray._private.arrow_serialization", "_register_custom_datasets_serializers", "pyarrow"),
          ("ray._common.pydantic_compat", "register_pydantic_serializers", "pydantic.v1.fields"),
          ("ray.util.serialization_addons", "register_starlette_serializer", "starlette.datastructures"))


def limit_malloc_arenas() -> bool:
    """Put ``MALLOC_ARENA_MAX`` (:data:`ARENAS`) into this process's environment, for the Ray node processes it is
    about to start (local mode, ``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`), unless the user
    set it or ``AERODAAS_MALLOC_ARENA_MAX`` is ``0``. Returns True when the variable is now in effect for children."""
    if os.environ.get("AERODAAS_MALLOC_ARENA_MAX", "").strip() == "0":
        return False
    os.environ.setdefault("MALLOC_ARENA_MAX", str(ARENAS))
    return True


def lean_worker_imports() -> bool:
    """Name :func:`worker_setup` as the setup hook of the Ray workers this process is about to start (see the
    module), unless ``AERODAAS_LEAN_WORKERS`` is ``0`` or another hook is set. Returns True when it is in effect."""
    if os.environ.get("AERODAAS_LEAN_WORKERS", "").strip() == "0":
        return False
    return os.environ.setdefault(SETUP_HOOK_ENV, SETUP_HOOK) == SETUP_HOOK


def worker_setup() -> None:
    """Ray worker setup hook: :func:`addons_only_when_imported` and :func:`one_blas_thread` in the worker (see the
    module)."""
    if addons_only_when_imported():
        one_blas_thread()


def one_blas_thread() -> bool:
    """Set ``OPENBLAS_NUM_THREADS`` to :data:`BLAS_THREADS` in this process's environment for the OpenBLAS that
    numpy will load (see the module), unless the user set it or numpy is already imported (too late: OpenBLAS read
    the environment when it loaded). Returns True when it is in effect."""
    if "numpy" in sys.modules:
        return False
    return os.environ.setdefault("OPENBLAS_NUM_THREADS", str(BLAS_THREADS)) == str(BLAS_THREADS)


def addons_only_when_imported() -> bool:
    """In this process, let each of Ray's serialisation add-ons of :data:`ADDONS` register only when its library is
    already imported, so that a process that never uses Arrow, Pydantic's v1 package or Starlette never imports
    them: a Ray worker (:func:`worker_setup`) or a run's driver, whose first actor creation otherwise imports them
    (pyarrow alone 0.11 s of CPU on the 2-core machine kind, a warm page cache; +30 MB). Ray's ``apply`` is replaced
    (it is looked up on its module at each call) by one that imports an add-on's module only when that add-on
    registers: Ray's ``pydantic_compat`` imports Pydantic itself, which a worker whose actor never uses Pydantic
    (an idle worker, the recorder of an unrecorded run) then does not import either. Done once per process;
    nothing when ``AERODAAS_LEAN_WORKERS`` is ``0``. Returns True when it is in effect."""
    if os.environ.get("AERODAAS_LEAN_WORKERS", "").strip() == "0":
        return False
    from ray.util import serialization_addons  # lazy: heavy ray (the hook runs in a worker that imported it)

    serialization_addons.apply = _apply_imported
    return True


def _apply_imported(context: object) -> None:
    """Ray's ``serialization_addons.apply(context)`` for the add-ons of :data:`ADDONS` whose library this process
    imported: each registered by Ray's own function, whose module is imported only then (Arrow's never on
    Windows, which Ray's ``apply`` skips too)."""
    for module, name, library in ADDONS:
        if library in sys.modules and not (library == "pyarrow" and sys.platform == "win32"):
            getattr(importlib.import_module(module), name)(context)
