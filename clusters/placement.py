"""Placement you can see before flying: computes that Ray cannot tell apart.

An actor of compute resource ``c`` is placed with ``label_selector={"tier": c.tier, **c.labels}``
(:meth:`aerodaas.runtime.dataflow.ActorPlan.selector`). Two computes of the same tier with the same labels (typically none)
get the same selector, so which of their nodes each actor lands on is Ray's choice (six drones over two unlabelled
edge computes landed 5 + 1). :func:`indistinct_computes` finds them in a plan; ``aerodaas plan`` and ``aerodaas run``
(on a cluster) print :func:`placement_warning`. :func:`compute_label` is the label that tells them apart, which
:class:`aerodaas.clusters.local.LocalCluster` callers and cluster files put on the node of each compute.

An actor that asks for GPUs (``num_gpus``) that no live node matching its selector has would wait
in Ray's queue for ever (Ray only logs that it is infeasible): :func:`gpu_placement_errors` finds them from
``ray.nodes()`` once Ray runs, before any actor is created, so ``aerodaas run`` stops with a message instead.
"""
from __future__ import annotations

import re
from typing import Any

__all__ = ["COMPUTE_LABEL", "compute_label", "indistinct_computes", "placement_warning", "selector_matches",
           "gpu_placement_errors"]

#: the node label naming the compute resource a node serves
COMPUTE_LABEL = "aerodaas/compute"


def compute_label(compute_id: str) -> dict[str, str]:
    """``{"aerodaas/compute": compute_id}``: the label of the node that serves ``compute_id`` (Ray label values:
    letters, digits, ``-_.``, at most 63 characters). Raises ``ValueError`` naming the id when it cannot be one."""
    if not re.fullmatch(r"[A-Za-z0-9]([A-Za-z0-9_.-]{0,61}[A-Za-z0-9])?", compute_id or ""):
        raise ValueError(f"compute id {compute_id!r} cannot be a Ray label value ({COMPUTE_LABEL})")
    return {COMPUTE_LABEL: compute_id}


def indistinct_computes(plan: Any) -> list[tuple[str, dict[str, str], list[str]]]:
    """Groups of two or more computes the plan's actors use whose selectors are equal: ``[(tier, labels,
    [compute ids])]`` (sorted). ``plan``: a :class:`aerodaas.runtime.dataflow.RunPlan`."""
    by_selector: dict[tuple, set[str]] = {}
    for a in plan.actors.values():
        if a.compute is None:
            continue
        key = (a.tier, tuple(sorted(a.labels.items())))
        by_selector.setdefault(key, set()).add(a.compute)
    return sorted((tier, dict(labels), sorted(ids)) for (tier, labels), ids in by_selector.items() if len(ids) > 1)


def placement_warning(plan: Any) -> str | None:
    """A warning naming the computes :func:`indistinct_computes` finds and the label that separates them, or None."""
    groups = indistinct_computes(plan)
    if not groups:
        return None
    parts = []
    for tier, labels, ids in groups:
        sel = ", ".join(f"{k}={v}" for k, v in {"tier": tier, **labels}.items())
        parts.append(f"computes {', '.join(repr(i) for i in ids)} all place with [{sel}]")
    return ("placement between them is Ray's choice: " + "; ".join(parts) + f". Give each compute a label (e.g. "
            f"labels: {{{COMPUTE_LABEL}: <compute id>}}) and start its node with it")


def selector_matches(selector: dict[str, str], labels: dict[str, str]) -> bool:
    """Whether a node with ``labels`` satisfies Ray's ``label_selector`` ``selector``: each value is an exact
    label value, ``!v`` (not v), ``in(a,b)`` or ``!in(a,b)`` (Ray's label selector syntax, Ray 2.49+
    ``ray.util.scheduling_strategies``/``label_selector``)."""
    for key, want in selector.items():
        have = labels.get(key)
        neg = want.startswith("!")
        body = want[1:] if neg else want
        if body.startswith("in(") and body.endswith(")"):
            ok = have in {v.strip() for v in body[3:-1].split(",")}
        else:
            ok = have == body
        if ok == neg:
            return False
    return True


def gpu_placement_errors(plan: Any, placement: Any, nodes: list[dict]) -> list[str]:
    """One message per actor of ``plan`` (a :class:`aerodaas.runtime.dataflow.RunPlan`) that asks for
    ``num_gpus`` and has no live node of ``nodes`` (``ray.nodes()``: ``Alive``, ``Labels``, ``Resources``) with
    that many GPUs (its total, not what is free now) and labels matching its selector on ``placement``; [] when
    every one can be placed. A GPU actor Ray cannot place would otherwise keep the run waiting for ever."""
    out = []
    for a in plan.actors.values():
        want = float(getattr(a, "num_gpus", 0.0) or 0.0)
        if want <= 0:
            continue
        sel = a.selector(placement)
        fits = [n for n in nodes if n.get("Alive") and selector_matches(sel, n.get("Labels") or {})]
        if any(float((n.get("Resources") or {}).get("GPU", 0.0)) >= want for n in fits):
            continue
        where = ", ".join(f"{k}={v}" for k, v in sel.items())
        gpus = [float((n.get("Resources") or {}).get("GPU", 0.0)) for n in fits]
        out.append(f"actor {a.name} asks for num_gpus={want:g} on a node [{where}], but no live node has that "
                   f"many GPUs ({len(fits)} node(s) match its labels, with {gpus or 'no'} GPUs); start a node of "
                   f"that compute with its GPUs (`ray start --num-gpus N --labels ...`), or set "
                   f"Providers(num_gpus=0) to run where it is placed without asking Ray for a GPU")
    return out
