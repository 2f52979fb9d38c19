"""Imported by :mod:`aerodaas.bench.isolation`'s fork server before it forks policy processes: the built-in
schedulers and LAPLAN's compiled planner, loaded once, so each fresh policy process starts warm (the server itself
never runs a policy, sees a harness, a trace or a seed)."""
from aerodaas.schedulers import (analytics_baselines, analytics_dems, analytics_evplan,  # noqa: F401
                                 analytics_gainplan, analytics_laplan, single_machine_jit)

single_machine_jit.warm_up()
