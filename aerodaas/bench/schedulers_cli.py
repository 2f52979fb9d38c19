"""``aerodaas bench schedulers``: its options (parsed at every ``aerodaas`` start, so this module imports nothing
beyond :mod:`aerodaas.bench.options`); the command itself, over the runtime benchmark
(:func:`aerodaas.bench.schedulers.run_schedulers`) and the policy harness (:mod:`aerodaas.bench.sweep`), is
:mod:`aerodaas.bench.schedulers_main`."""
from __future__ import annotations

import argparse
import json
import math
from typing import Any

from aerodaas.bench.options import DEFAULT_DRONES_PER_EDGE, DEFAULT_FPS, EMULATION_BOUND_MS, LOADS, SCENARIOS
from aerodaas.bench.options import positive_int as _positive_int  # argparse type: an integer >= 1


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
    p.set_defaults(func=_run)
    return p


def _run(args: argparse.Namespace) -> int:
    from aerodaas.bench.schedulers_main import main  # lazy: CLI start-up

    return main(args)
