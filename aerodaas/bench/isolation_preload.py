"""Imported by :mod:`aerodaas.bench.isolation`'s fork server before it forks policy processes: the built-in
schedulers, LAPLAN's compiled planner and the plug-in registry's reads of the installed distributions, loaded
once, so each fresh policy process starts warm (the server itself never runs a policy, sees a harness, a trace or
a seed). Without those reads, every policy process named ``"module.path:Class"`` would read every installed
distribution's metadata and file list before importing its class (about 0.1 CPU-s each)."""
from aerodaas.schedulers import (analytics_baselines, analytics_dems, analytics_evplan,  # noqa: F401
                                 analytics_gainplan, analytics_laplan, single_machine_jit)
from aerodaas.plugins.registry import installed_top_level_packages
from aerodaas.schedulers.analytics_base import analytics_scheduler_names

single_machine_jit.warm_up()
analytics_scheduler_names()  # the entry points of every installed distribution
installed_top_level_packages()
