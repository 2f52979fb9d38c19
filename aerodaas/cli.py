"""The ``aerodaas`` command line: ``run``, ``info``, ``schema``, ``sim``, ``mission`` and more.

Each sub-command is a module with its parser and handler (``add_parser(sub)``), listed in
:data:`aerodaas.commands.COMMAND_MODULES`; this module only builds the parser from them and runs the handler."""
from __future__ import annotations

import argparse
import os
import signal
import sys

from aerodaas.commands import COMMAND_MODULES


def console() -> int:
    """The ``aerodaas`` command (console script and ``python -m aerodaas.cli``): :func:`main` as the process's own
    command, whose late-signal handler then stays installed until the process exits. An attached ``aerodaas run``
    goes to the warm driver of ``aerodaas up`` when one listens (:mod:`aerodaas.clusters.warm_client`)."""
    from aerodaas.clusters.warm_client import delegate  # lazy: the standard library only

    code = delegate(sys.argv)
    return main(own_process=True) if code is None else code


def build_parser() -> argparse.ArgumentParser:
    """The ``aerodaas`` parser: each module of :data:`aerodaas.commands.COMMAND_MODULES` adds its sub-command(s)."""
    p = argparse.ArgumentParser(prog="aerodaas", description="AeroDaaS: drones-as-a-service on Ray")
    sub = p.add_subparsers(dest="cmd", required=True)
    for module in COMMAND_MODULES:
        module.add_parser(sub)
    return p


def main(argv: list[str] | None = None, *, own_process: bool = False) -> int:
    """The ``aerodaas`` command line (``argv``: its arguments; default ``sys.argv[1:]``); returns the exit code."""
    p = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["inject"]:  # its values may start with '-' (a token, a waypoint south-west of home)
        from aerodaas.tools.hitl_client import inject_argv  # lazy: only for inject

        argv = inject_argv(argv)
    args = p.parse_args(argv)
    args.own_process = own_process  # read by `aerodaas run` (its late-signal handler stays installed to the exit)
    try:
        return args.func(args)
    except BrokenPipeError:  # `aerodaas info FILE | head`: the reader left; end quietly like any Unix filter
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())  # Python's final flush of stdout must not fail again
        except OSError:
            pass
        return 128 + signal.SIGPIPE


if __name__ == "__main__":
    sys.exit(console())
