"""``aerodaas bench schedulers`` itself (its options: :mod:`aerodaas.bench.schedulers_cli`): which options each mode
uses, the runtime benchmark (:func:`aerodaas.bench.schedulers.run_schedulers`) or the policy harness
(:mod:`aerodaas.bench.sweep`), and the report."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from aerodaas.bench.bound import Budget
from aerodaas.bench.options import DEFAULT_DRONES_PER_EDGE, EMULATION_BOUND_MS, LOADS
from aerodaas.bench.output import print_report
from aerodaas.bench.schedulers import run_schedulers
from aerodaas.bench.schedulers_report import compare_with_harness, format_table, write_plot
from aerodaas.bench.sweep import DEFAULT_SCHEDULERS, format_sweep, run_sweep
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers.analytics_base import iter_schedulers


#: the TraceSpec parameters set by ``--trace-<name>`` options (``_`` as ``-``)
TRACE_PARAMS = ("jitter", "drop", "joins", "leaves", "alpha", "on_s", "off_s", "stall_s", "stall_every_s",
                "flush_gap_ms")


def trace_spec(args: argparse.Namespace):
    """The :class:`aerodaas.bench.traces.TraceSpec` of the ``--trace*`` options of :func:`trace_options`. Raises
    ValueError naming the field, and for an option the kind does not use."""
    return TraceSpec.parse(args.trace, **{k: getattr(args, f"trace_{k}") for k in TRACE_PARAMS})


#: options only one mode uses (attribute -> option): given to the other mode, they are refused (the
#: harness ignored --network-variability and --cloud-jitter: a const:500 network gave the same utility as none)
RUNTIME_ONLY = {"network_variability": "--network-variability", "cloud_jitter": "--cloud-jitter",
                "cloud_nodes": "--cloud-nodes", "edge_hosts": "--edge-hosts",
                "cloud_reply_lead_ms": "--cloud-reply-lead-ms", "emulation_bound_ms": "--emulation-bound-ms",
                "compare_harness": "--compare-harness", "repeat": "--repeat", "address": "--address"}
HARNESS_ONLY = {"processes": "--processes", "no_bound": "--no-bound", "exact_bound": "--exact-bound",
                "exact_bound_budget_s": "--exact-bound-budget-s", "exact_bound_memory_mb": "--exact-bound-memory-mb"}


def unused_options(args: argparse.Namespace) -> list[str]:
    """The options given (not None / not False) that the chosen mode (``--harness`` or the runtime) does not use."""
    other = RUNTIME_ONLY if args.harness else HARNESS_ONLY
    return [opt for attr, opt in other.items() if getattr(args, attr, None) not in (None, False)]


#: the scheduler options with an option of their own (attribute -> option), like ``--option KEY=JSON``: refused when
#: no scheduler of the run takes them (`--estimator` with EDGE_EDF alone was accepted and did nothing)
SCHEDULER_OPTIONS = {"estimator": "--estimator", "eviction_scan": "--eviction-scan"}


def refused(args: argparse.Namespace) -> str | None:
    """Why the options given cannot run as asked (the message names every option concerned), None when they can:
    an option the chosen mode does not use (:func:`unused_options`), ``--cloud-sigma`` with ``--cloud-jitter`` on
    the runtime (the sigma sweep replaces the jitter: one of the two would be ignored), and a scheduler option
    (``--estimator``, ``--eviction-scan``, ``--option KEY``) that no scheduler of the run takes (the run's
    schedulers: ``--schedulers``, else the mode's default set), or an unknown scheduler name."""
    unused = unused_options(args)
    if unused:  # an option this mode does not use would be silently ignored: its result would not be what was asked
        mode, other = ("--harness", "the runtime (without --harness)") if args.harness else \
            ("the runtime", "--harness")
        return (f"{', '.join(unused)}: not used by {mode} (only by {other}); drop "
                f"{'it' if len(unused) == 1 else 'them'}")
    if not args.harness and args.cloud_sigma and args.cloud_jitter:
        return ("--cloud-sigma, --cloud-jitter: --cloud-sigma sweeps lognormal cloud jitters in place of "
                "--cloud-jitter, which would be ignored; give one of the two")
    names = DEFAULT_SCHEDULERS if args.schedulers is None and args.harness else args.schedulers
    try:
        classes = iter_schedulers(names)
    except ValueError as e:
        return str(e)
    given = [(opt, attr) for attr, opt in SCHEDULER_OPTIONS.items() if getattr(args, attr, None) is not None]
    given += [(f"--option {key}", key) for key, _ in args.option]
    for opt, key in given:  # an option no scheduler of the run has is a typo or a no-op, not a setting
        if not any(key in cls.options for cls in classes):
            return f"{opt}: no scheduler of this run has it ({', '.join(c.name for c in classes)}); drop it"
    return None


def _run_harness(args: argparse.Namespace, options: dict) -> dict:
    def progress(done: int, total: int) -> None:
        if done == total or done % max(1, total // 20) == 0:
            print(f"[bench schedulers --harness] {done}/{total} jobs", file=sys.stderr, flush=True)

    return run_sweep(loads=args.load or list(LOADS), sigmas=args.cloud_sigma or [0.0, 0.05, 0.1, 0.2],
                     drones_per_edge=args.drones_per_edge or [2, 3], scenarios=args.scenarios or ["none", "step"],
                     seeds=list(range(args.seed, args.seed + args.seeds)), drones=args.drones,
                     duration_s=args.duration or 120.0, fps=args.fps, schedulers=args.schedulers, options=options,
                     edge_jitter=args.edge_jitter, processes=args.processes, bound=not args.no_bound,
                     exact_bound_loads=args.exact_bound or ["HEAVY"], progress=progress, trace=trace_spec(args),
                     bound_budget=Budget(args.exact_bound_budget_s or Budget.time_s,
                                         args.exact_bound_memory_mb or Budget.memory_mb))


def _run_runtime(args: argparse.Namespace, options: dict) -> dict:
    out = None
    for dpe in args.drones_per_edge or [DEFAULT_DRONES_PER_EDGE]:
        res = run_schedulers(args.schedulers, args.load or ["MEDIUM"], args.drones or 80, args.duration or 60.0,
                             args.seed, dpe, args.fps, args.network_variability, args.edge_jitter,
                             args.cloud_jitter or "lognormal:0.1",
                             1 if args.cloud_nodes is None else args.cloud_nodes, None, args.edge_hosts, args.address,
                             args.repeat or 1,
                             reply_lead_ms=100.0 if args.cloud_reply_lead_ms is None else args.cloud_reply_lead_ms,
                             seeds=args.seeds, cloud_sigmas=args.cloud_sigma, scenarios=args.scenarios,
                             options=options, emulation_bound_ms=args.emulation_bound_ms or EMULATION_BOUND_MS,
                             trace=trace_spec(args))
        if args.compare_harness:
            res["harness_comparison"] = compare_with_harness(res)
        if out is None:
            out = res
        else:  # several drones-per-edge settings: one result, runs and rows of every setting
            out["runs"] += res["runs"]
            out["results"] += res["results"]
            out.setdefault("harness_comparison", []).extend(res.get("harness_comparison", []))
            out.setdefault("per_drones_per_edge_config", []).append(res["config"])
    return out


def _significant(x, digits: int):
    """``x`` (nested dicts/lists of JSON values) with every float rounded to ``digits`` significant digits."""
    if isinstance(x, float):
        return float(f"{x:.{digits}g}")
    if isinstance(x, dict):
        return {k: _significant(v, digits) for k, v in x.items()}
    if isinstance(x, list):
        return [_significant(v, digits) for v in x]
    return x


def main(args: argparse.Namespace) -> int:
    """``aerodaas bench schedulers`` with the options of :mod:`aerodaas.bench.schedulers_cli`: refuses options the
    run would ignore (exit 2 naming them), runs the runtime benchmark or the harness, writes and prints the report;
    returns 0, or 1 when a runtime run's accounting is incomplete."""
    options = {k: v for k, v in (("estimator", args.estimator), ("eviction_scan", args.eviction_scan)) if v}
    options.update(args.option)
    why = refused(args)
    if why:
        print(f"aerodaas bench schedulers: {why}", file=sys.stderr)
        return 2
    try:
        res = _run_harness(args, options) if args.harness else _run_runtime(args, options)
    except ValueError as e:
        print(f"aerodaas bench schedulers: {e}", file=sys.stderr)
        return 2
    # compact, floats to 8 significant digits (far below any CI): the 5-seed sweep keeps every per-seed value of
    # 320 results and was 2 MB indented at full float precision
    text = json.dumps(_significant(res, 8), separators=(",", ":"))
    try:
        if args.out:
            Path(args.out).write_text(text + "\n", encoding="utf-8")
        if args.plot:
            write_plot(res, args.plot)
            print(f"aerodaas bench schedulers: comparison figure written to {args.plot}", file=sys.stderr)
    except OSError as e:
        print(f"aerodaas bench schedulers: cannot write output: {e}", file=sys.stderr)
        return 2

    if args.harness:
        print_report(text if args.json else format_sweep(res))
        return 0
    print_report(text if args.json else format_table(res))
    bad = [r for r in res["runs"] if r["accounting"]["pending"] or r["accounting"]["terminal"] != r["tasks"]]
    return 1 if bad else 0
