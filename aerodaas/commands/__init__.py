"""The ``aerodaas`` sub-commands: one module each, holding its parser and its handler.

Every command module has ``add_parser(sub)``, which adds its sub-parser(s) to ``sub`` (an argparse
sub-parsers action) and sets ``func`` to the handler, a function ``(argparse.Namespace) -> int`` returning the exit
code. :data:`COMMAND_MODULES` lists them in the order ``aerodaas --help`` shows them; :mod:`aerodaas.cli` imports
each's ``add_parser``. A new command is a new module here and a line in that tuple.
"""
from __future__ import annotations

from types import ModuleType

from aerodaas.commands import (bench, cluster, info, inject, label, layout, merge, plan, plot, plugins, recover, replay,
                               run, schema, sim, train)
from aerodaas.tools import mission_cli, signing_cli

#: the modules of the sub-commands, in help order; ``mission`` and ``mavlink signing`` live beside the tools they
#: drive (:mod:`aerodaas.tools.mission_cli`, :mod:`aerodaas.tools.signing_cli`) and follow the same contract
COMMAND_MODULES: tuple[ModuleType, ...] = (
    run,            # run
    cluster,        # up, down
    plan,           # plan
    replay,         # replay
    layout,         # layout
    info,           # info
    schema,         # schema
    plugins,        # plugins
    train,          # train
    label,          # label
    recover,        # recover
    merge,          # merge
    inject,         # inject
    plot,           # plot
    sim,            # sim
    mission_cli,    # mission
    signing_cli,    # mavlink signing
    bench,          # bench
)
