"""The label-setting DP of :func:`aerodaas.schedulers.single_machine.max_gain_schedule`, compiled with numba.

Why: LAPLAN re-plans with this DP on the dispatcher's event path, ~1,000-1,800 labels per plan over 40-65 task
groups; in CPython that took 1-5 ms per plan (p99 of the decision time ~4.5-5 ms idle, 6-15 ms loaded).
Compiled, the same DP takes ~0.05-0.2 ms.

Same algorithm, same answer: this is a line-by-line port of the Python loop (same float64 arithmetic, same ``_EPS``
comparisons, the same (free time, push counter) heap order, the stored labels kept in insertion order as the
Python dict keeps them), so it returns the same schedule, ties included (tested against the pure-Python loop in
``tests/schedulers/test_laplan_planner_equivalence.py``). Differences of representation only: a used-job set is a ``uint64``
bit mask (so at most :data:`MAX_GROUPS` groups; the caller falls back to Python above), a path is a node index
(job, start, parent) instead of a nested tuple, and the store of labels is scanned for a subset key instead of
enumerating the submasks of a mask (both find whether some stored key is a subset of it with enough gain).

numba (https://numba.readthedocs.io, nopython mode, ``cache=True``) is imported lazily on the first call, so
importing the schedulers does not pay for it; the first call compiles (a few seconds, or loads the on-disk cache).
:func:`available` says whether it can be used (numba importable and ``AERODAAS_NO_JIT`` unset).
"""
from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["MAX_GROUPS", "available", "import_error", "prepare", "solve", "status", "warm_up"]

#: the most task groups a uint64 mask holds
MAX_GROUPS = 64

class _Compiled(NamedTuple):
    """The compiled functions once loaded (``kernel``, ``prepare``; both None when numba could not be imported,
    ``error`` then says why)."""

    kernel: Callable[..., Any] | None
    prepare: Callable[..., Any] | None
    error: ImportError | None


@functools.cache
def _compiled() -> _Compiled:
    """Import the numba kernel, once per process (``functools.cache``: the import's outcome, kept; no module-level
    variable rebound with ``global``)."""
    try:
        from aerodaas.schedulers import single_machine_kernel as k  # lazy: optional numba
    except ImportError as e:  # numba not installed: the pure-Python loop is used
        return _Compiled(None, None, e)
    return _Compiled(k.kernel, k.prepare, None)


def available() -> bool:
    """True if the compiled kernel can be used (compiling it on the first call); False if numba is missing or
    ``AERODAAS_NO_JIT`` is set (then :func:`solve` must not be called)."""
    if os.environ.get("AERODAAS_NO_JIT"):
        return False
    return _compiled().kernel is not None


def import_error() -> ImportError | None:
    """Why the compiled kernel cannot be used: the ImportError of numba, None when it imported (tries the import on
    the first call, as :func:`available` does)."""
    return _compiled().error


def status() -> dict:
    """Whether LAPLAN's planner runs compiled in this process, for a benchmark's JSON (it shapes results: only
    compiled are plans above :data:`MAX_GROUPS` task groups reduced to fit the kernel, else the Python DP solves
    them whole): ``{"compiled": bool, "why_not": None | str}``, ``why_not`` naming ``AERODAAS_NO_JIT`` or the
    import error of numba. Calls :func:`available` (imports numba on the first call: about a second)."""
    compiled = available()
    if compiled:
        why = None
    elif os.environ.get("AERODAAS_NO_JIT"):
        why = "AERODAAS_NO_JIT is set"
    else:
        err = import_error()
        why = f"{type(err).__name__}: {err}"
    return {"compiled": compiled, "why_not": why}


def solve(rel, proc, bit, vstart, latest, best, gains, eps: float):
    """Run the DP. Arrays (groups sorted by release, as the Python loop's ``gs``): ``rel``/``proc`` (G,) float64 ms,
    ``bit`` (G,) uint64, ``vstart`` (G + 1,) int64 offsets into ``latest`` (V,) float64 latest starts (ascending per
    group) and ``best`` (V,) int64 (the suffix-best job index), ``gains`` (J,) float64. Returns ``(best gain,
    node_j, node_t, node_parent, best node)``: the best path is the chain of nodes from ``best node`` (-1: empty)."""
    return _compiled().kernel(rel, proc, bit, vstart, latest, best, gains, eps)


def prepare(r, d, p, w, gid, ngroups: int, free_at: float, eps: float):
    """Build :func:`solve`'s arrays from flat job arrays (``r``/``d``/``p``/``w`` (J,) float64 ms and gain, ``gid``
    (J,) int64 group in ``[0, ngroups)``), compiled; see ``single_machine_kernel.prepare``. Returns ``(code, rel,
    proc, bit, vstart, latest, best)``, code 0 ok, 1 a group's jobs differ in release or processing time, 2 more
    than :data:`MAX_GROUPS` groups live at once. Only after :func:`available` returned True."""
    return _compiled().prepare(r, d, p, w, gid, ngroups, free_at, eps, MAX_GROUPS)


def warm_up() -> bool:
    """Compile (or load from numba's cache) the kernel now, on a one-job instance, so that the first plan of a run
    does not pay for it (seconds). Returns :func:`available`."""
    if not available():
        return False

    solve(np.zeros(1), np.ones(1), np.ones(1, np.uint64), np.array([0, 1], np.int64), np.zeros(1),
          np.zeros(1, np.int64), np.ones(1), 1e-9)
    prepare(np.zeros(1), np.ones(1), np.ones(1), np.ones(1), np.zeros(1, np.int64), 1, 0.0, 1e-9)
    return True
