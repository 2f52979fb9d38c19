"""``aerodaas bench schedulers``: its command line (options, their checks, which mode uses which) over the runtime
benchmark (:func:`aerodaas.bench.schedulers.run_schedulers`) and the policy harness (:mod:`aerodaas.bench.sweep`)."""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from aerodaas.bench.schedulers import (DEFAULT_DRONES_PER_EDGE, DEFAULT_FPS, EMULATION_BOUND_MS, LOADS,
                                       run_schedulers)
from aerodaas.bench.schedulers_report import compare_with_harness, format_table, write_plot
from aerodaas.bench.tours import _positive as _positive_int  # argparse type: an integer >= 1

def scheduler_option(text: str) -> tuple[str, Any]:
    """``--option KEY=JSON`` (e.g. ``replan_tolerance_ms=0``): the key and its JSON value. Raises
    argparse.ArgumentTypeError naming the text when it is not KEY=JSON."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY=JSON, e.g. replan_tolerance_ms=0")
    try:
        return key.strip(), json.loads(raw)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: the value is not JSON ({e.msg})") from None


def _positive_float(s: str) -> float:
    v = float(s)
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {s}")
    return v


def _loads(s: str) -> list[str]:
    out = [x.strip().upper() for x in s.split(",") if x.strip()]
    bad = [x for x in out if x not in LOADS]
    if bad or not out:
        raise argparse.ArgumentTypeError(f"loads must be among {', '.join(LOADS)} (comma-separated), got {s!r}")
    return out


def _floats(s: str) -> list[float]:
    try:
        out = [float(x) for x in s.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {s!r}") from None
    if not out or any(not (v >= 0 and math.isfinite(v)) for v in out):
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers >= 0, got {s!r}")
    return out


def _ints(s: str) -> list[int]:
    try:
        out = [int(x) for x in s.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {s!r}") from None
    if not out or any(v < 1 for v in out):
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 1, got {s!r}")
    return out


def _scenarios(s: str) -> list[str]:
    from aerodaas.bench.sweep import SCENARIOS

    out = [x.strip() for x in s.split(",") if x.strip()]
    bad = [x for x in out if x not in SCENARIOS]
    if bad or not out:
        raise argparse.ArgumentTypeError(f"scenarios must be among {', '.join(SCENARIOS)}, got {s!r}")
    return out


def _fleet_options(p: argparse.ArgumentParser) -> None:
    """``aerodaas bench schedulers`` options: the fleet, its loads and seeds (both modes)."""
    g = p.add_argument_group("the fleet, its loads and seeds (both modes)")
    g.add_argument("--harness", action="store_true",
                   help="run the deterministic policy harness (no Ray) over the sweep instead of the Ray runtime")
    g.add_argument("--drones", type=_positive_int,
                   help="drones in the fleet (default 80 on the runtime; 4 edges' worth in --harness)")
    g.add_argument("--load", type=_loads,
                   help="LIGHT, MEDIUM or HEAVY, or a comma-separated list (default MEDIUM; --harness: all three)")
    g.add_argument("--duration", type=_positive_float, help="seconds of arrivals per run (default 60; --harness 120)")
    g.add_argument("--schedulers", nargs="+", metavar="NAME", help="schedulers to run (default: all registered; "
                                                                   "--harness: EDGE_EDF, CLOUD, E+C, the DEMS family, "
                                                                   "GAINPLAN, EVPLAN, LAPLAN)")
    g.add_argument("--seed", type=int, default=0, help="first seed of the traces and draws (default 0)")
    g.add_argument("--seeds", type=_positive_int, default=5, help="seeds per configuration (default 5)")
    g.add_argument("--drones-per-edge", type=_ints,
                   help=f"drones linked to each edge device, comma-separated to sweep (default "
                        f"{DEFAULT_DRONES_PER_EDGE}; --harness 2,3)")
    g.add_argument("--cloud-sigma", type=_floats,
                   help="lognormal cloud-time jitter sigmas to sweep, comma-separated (default: --cloud-jitter on the "
                        "runtime; --harness 0,0.05,0.1,0.2)")
    g.add_argument("--scenarios", type=_scenarios,
                   help="network-variability scenarios to sweep: none, step, walk (default none; --harness none,step, "
                        "run at HEAVY)")
    g.add_argument("--fps", type=_positive_float, default=DEFAULT_FPS,
                   help=f"frames (1-frame batches) per second per drone (default {DEFAULT_FPS:g})")
    g.add_argument("--edge-jitter", default="lognormal:0.05", help="edge hold jitter (default lognormal:0.05)")


def _policy_options(p: argparse.ArgumentParser) -> None:
    """``aerodaas bench schedulers`` options: options of the schedulers."""
    g = p.add_argument_group("options of the schedulers")
    g.add_argument("--estimator", help="fair-margin option: one cloud-latency estimator for every just-in-time "
                                       "policy: profile, mean[:K], max[:K] or pQ[:K]")
    g.add_argument("--eviction-scan", choices=("reference", "full"),
                   help="DEM/DEMS eviction scan: reference (PriorityQueue.add, the default) or full")
    g.add_argument("--option", type=scheduler_option, action="append", default=[], metavar="KEY=JSON",
                   help="a scheduler option for every scheduler of the run that has it, e.g. replan_tolerance_ms=0 "
                        "(LAPLAN); repeatable")


def trace_options(p: argparse.ArgumentParser, default: str = "periodic") -> None:
    """The arrival trace's options (``--trace KIND`` and its ``--trace-*`` parameters, read back with
    :func:`trace_spec`) on ``p``: ``aerodaas bench schedulers`` and ``python -m aerodaas.bench.decision_time``
    (``default``: the kind without ``--trace``)."""
    g = p.add_argument_group("the arrival trace")
    g.add_argument("--trace", default=default, metavar="KIND",
                   help="arrival process: periodic, realistic (jittered gaps, dropped frames, drones joining "
                        "mid-run), pareto (heavy-tailed gaps), onoff (bursts and silences), flush (a link that stalls "
                        "and flushes its buffered frames) or recording:FILE.mcap (the camera-frame gaps of a "
                        "recording, scaled to the frame rate); every kind keeps the mean frame rate (default "
                        "%(default)s)")
    g.add_argument("--trace-jitter", type=float, metavar="FRACTION",
                   help="realistic: each frame gap x (1 + U(-f, f)) (default 0.2)")
    g.add_argument("--trace-drop", type=float, metavar="P", help="realistic/recording: frame loss probability "
                                                                 "(default 0.1 realistic, 0 recording)")
    g.add_argument("--trace-joins", type=int, metavar="N", help="drones per edge joining mid-run (default 1 realistic)")
    g.add_argument("--trace-leaves", type=int, metavar="N", help="drones per edge leaving mid-run (default 0)")
    g.add_argument("--trace-alpha", type=float, metavar="A", help="pareto: the gaps' Pareto shape, > 1 (default 1.5)")
    g.add_argument("--trace-on-s", type=float, metavar="S", help="onoff: seconds of frames per burst (default 3)")
    g.add_argument("--trace-off-s", type=float, metavar="S", help="onoff: seconds of silence after a burst (default 3)")
    g.add_argument("--trace-stall-s", type=float, metavar="S", help="flush: mean stall of the link (default 2 s)")
    g.add_argument("--trace-stall-every-s", type=float, metavar="S",
                   help="flush: mean time the link is up between stalls (default 6 s)")
    g.add_argument("--trace-flush-gap-ms", type=float, metavar="MS",
                   help="flush: gap between the buffered frames delivered after a stall (default 2 ms)")


def _harness_options(p: argparse.ArgumentParser) -> None:
    """``aerodaas bench schedulers`` options: --harness only."""
    g = p.add_argument_group("--harness only")
    g.add_argument("--processes", type=_positive_int, help="--harness worker processes (default: min(2, CPUs))")
    g.add_argument("--no-bound", action="store_true", help="--harness: skip the upper bounds")
    g.add_argument("--exact-bound", type=_loads, default=None, metavar="LOADS",
                   help="--harness: loads whose cells also get the exact and non-anticipative bounds (default HEAVY)")
    g.add_argument("--exact-bound-budget-s", type=_positive_float, metavar="S",
                   help="--harness: wall-clock seconds each edge's exact bound may take (default 120); past it the "
                        "bound is reported 'not computed' beside the LP bound")
    g.add_argument("--exact-bound-memory-mb", type=_positive_float, metavar="MIB",
                   help="--harness: memory each edge's exact bound may take (default 1024 MiB)")


def _runtime_options(p: argparse.ArgumentParser) -> None:
    """``aerodaas bench schedulers`` options: the Ray runtime only."""
    g = p.add_argument_group("the Ray runtime only")
    g.add_argument("--network-variability", action="append", metavar="SPEC",
                   help="extra cloud latency: const:MS, normal:MEAN,SD, lognormal:MEDIAN,SIGMA, +MS@T1-T2 (episode, "
                        "seconds), walk:STEP,MAX[,EVERY]; repeatable")
    g.add_argument("--cloud-jitter", help="runtime: cloud hold jitter (default lognormal:0.1; not with --cloud-sigma, "
                                          "which sweeps lognormal jitters instead, as --harness does)")
    g.add_argument("--cloud-nodes", type=int, help="runtime: cloud nodes of the local cluster (default 1)")
    g.add_argument("--edge-hosts", type=_positive_int,
                   help="edge host actors (default: CPUs + 1, at most one per edge)")
    g.add_argument("--cloud-reply-lead-ms", type=float,
                   help="emulated cloud replies are sent this early and released when due (default 100; 0: off)")
    g.add_argument("--emulation-bound-ms", type=_positive_float,
                   help=f"a runtime run whose worst timing error p99 exceeds this is marked invalid (default "
                        f"{EMULATION_BOUND_MS:g})")
    g.add_argument("--compare-harness", action="store_true",
                   help="runtime: also run the harness on the same traces and draws and say whether each result lies "
                        "within the harness's CI")
    g.add_argument("--repeat", type=_positive_int, help="runtime: runs per scheduler, load and seed (default 1)")
    g.add_argument("--address", help="run on this Ray cluster (e.g. 'auto') instead of starting a local one")


def _output_options(p: argparse.ArgumentParser) -> None:
    """``aerodaas bench schedulers`` options: output."""
    g = p.add_argument_group("output")
    g.add_argument("--json", action="store_true", help="print the result as JSON instead of a table")
    g.add_argument("--out", metavar="FILE", help="also write the JSON result to FILE")
    g.add_argument("--plot", metavar="PNG", help="write the comparison figure to PNG (default: no figure; a "
                                                 "benchmark writes no file it was not given)")


def add_parser(bench_subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``aerodaas bench schedulers`` on the ``bench`` sub-command's subparsers."""
    p = bench_subparsers.add_parser(
        "schedulers", help="analytics schedulers (edge/cloud placement): seeded drone-fleet traces, mean ± 95 %% CI "
                           "over seeds, on Ray actors or (--harness) on the deterministic policy harness",
        description="Every analytics scheduler on the same seeded arrival traces: on-time rate, utility, cloud cost, "
                    "drops and behaviour counters as mean ± 95%% CI over --seeds. Default: emulated with wall-clock "
                    "time on Ray actors (edge node + cloud nodes), with the emulation's own timing error (a run over "
                    "--emulation-bound-ms is marked invalid). --harness: the same policies and draws on simulated "
                    "time, no Ray, swept over --cloud-sigma x --drones-per-edge x --scenarios, with upper bounds (LP; at "
                    "HEAVY also the exact offline optimum and the non-anticipative bound).")
    _fleet_options(p)
    _policy_options(p)
    trace_options(p)
    _harness_options(p)
    _runtime_options(p)
    _output_options(p)
    p.set_defaults(func=_cmd)
    return p


#: the TraceSpec parameters set by ``--trace-<name>`` options (``_`` as ``-``)
TRACE_PARAMS = ("jitter", "drop", "joins", "leaves", "alpha", "on_s", "off_s", "stall_s", "stall_every_s",
                "flush_gap_ms")


def trace_spec(args: argparse.Namespace):
    """The :class:`aerodaas.bench.traces.TraceSpec` of the ``--trace*`` options of :func:`trace_options`. Raises
    ValueError naming the field, and for an option the kind does not use."""
    from aerodaas.bench.traces import TraceSpec

    return TraceSpec.parse(args.trace, **{k: getattr(args, f"trace_{k}") for k in TRACE_PARAMS})


#: options only one mode uses (attribute -> option): given to the other mode, they are refused (issue 41.4: the
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
#: no scheduler of the run takes them (issue 41.4: `--estimator` with EDGE_EDF alone was accepted and did nothing)
SCHEDULER_OPTIONS = {"estimator": "--estimator", "eviction_scan": "--eviction-scan"}


def refused(args: argparse.Namespace) -> str | None:
    """Why the options given cannot run as asked (the message names every option concerned), None when they can:
    an option the chosen mode does not use (:func:`unused_options`), ``--cloud-sigma`` with ``--cloud-jitter`` on
    the runtime (the sigma sweep replaces the jitter: one of the two would be ignored), and a scheduler option
    (``--estimator``, ``--eviction-scan``, ``--option KEY``) that no scheduler of the run takes (the run's
    schedulers: ``--schedulers``, else the mode's default set), or an unknown scheduler name."""
    from aerodaas.schedulers.analytics_base import iter_schedulers

    unused = unused_options(args)
    if unused:  # an option this mode does not use would be silently ignored: its result would not be what was asked
        mode, other = ("--harness", "the runtime (without --harness)") if args.harness else \
            ("the runtime", "--harness")
        return (f"{', '.join(unused)}: not used by {mode} (only by {other}); drop "
                f"{'it' if len(unused) == 1 else 'them'}")
    if not args.harness and args.cloud_sigma and args.cloud_jitter:
        return ("--cloud-sigma, --cloud-jitter: --cloud-sigma sweeps lognormal cloud jitters in place of "
                "--cloud-jitter, which would be ignored; give one of the two")
    if args.schedulers is None and args.harness:
        from aerodaas.bench.sweep import DEFAULT_SCHEDULERS as names
    else:
        names = args.schedulers
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
    from aerodaas.bench.bound import Budget
    from aerodaas.bench.sweep import run_sweep

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


def _cmd(args: argparse.Namespace) -> int:
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
    from aerodaas.bench.output import print_report

    if args.harness:
        from aerodaas.bench.sweep import format_sweep

        print_report(text if args.json else format_sweep(res))
        return 0
    print_report(text if args.json else format_table(res))
    bad = [r for r in res["runs"] if r["accounting"]["pending"] or r["accounting"]["terminal"] != r["tasks"]]
    return 1 if bad else 0
