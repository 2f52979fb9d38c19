"""The ``aerodaas`` sub-commands, one module per command, all of one shape.

A command ``NAME`` is the module ``aerodaas/commands/NAME.py`` with ``add_parser(sub)``, which adds its sub-parser(s)
to ``sub`` (an argparse sub-parsers action) and sets ``func`` to its handler, a function
``(argparse.Namespace) -> int`` returning the exit code. A handler is named ``run`` (a single command) or
``run_<sub-command>`` (one per sub-command of a group: ``run_up``, ``run_push``, ``run_detector``). Handlers are
thin: they check and convert the options and print; the work is an ordinary, documented function of the concept's
package (``aerodaas.runtime``, ``aerodaas.labelling``, ``aerodaas.training``, ``aerodaas.tools`` ...), imported
inside the handler (``# lazy: CLI start-up``), so that ``import aerodaas.commands`` stays free of Ray, NumPy, OpenCV,
onnxruntime and pydantic. There are no ``*_main.py`` modules here. ``bench`` is a group whose sub-commands, the
benchmarks, register themselves (:func:`aerodaas.bench.parsers.add_parsers`). :data:`COMMAND_MODULES` lists the
modules in the order ``aerodaas --help`` shows them; :mod:`aerodaas.cli` calls each one's ``add_parser``. A new
command is a new module here and a line in that tuple; ``tests/architecture/test_cli_commands.py`` holds the shape.
"""
from __future__ import annotations

from types import ModuleType

from aerodaas.commands import (bench, cluster, info, inject, label, layout, mavlink, merge, mission, plan, plot, plugins,
                               recover, replay, run, schema, sim, train)

#: the modules of the sub-commands, in help order
COMMAND_MODULES: tuple[ModuleType, ...] = (
    run,            # run
    cluster,        # up, down
    plan,           # plan
    replay,         # replay
    layout,         # layout
    info,           # info
    schema,         # schema
    plugins,        # plugins
    train,          # train detector
    label,          # label frames, push, pull, serve
    recover,        # recover
    merge,          # merge
    inject,         # inject
    plot,           # plot
    sim,            # sim
    mission,        # mission upload, download
    mavlink,        # mavlink signing
    bench,          # bench
)
