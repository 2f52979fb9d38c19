"""One way to add a command: every ``aerodaas`` sub-command comes from a module of
:data:`aerodaas.commands.COMMAND_MODULES` that holds both its parser and its handler; ``aerodaas/cli.py`` only
assembles them."""
from __future__ import annotations

import argparse
import ast
from pathlib import Path

from aerodaas import cli
from aerodaas.commands import COMMAND_MODULES

ROOT = Path(__file__).resolve().parents[2]


def _sub_commands(module) -> dict[str, argparse.ArgumentParser]:
    """The sub-parsers ``module.add_parser`` adds to a fresh sub-parsers action, by command name."""
    sub = argparse.ArgumentParser(prog="t").add_subparsers(dest="cmd")
    module.add_parser(sub)
    return dict(sub.choices)


def test_each_command_module_adds_commands_whose_handler_it_holds():
    seen: dict[str, str] = {}
    for module in COMMAND_MODULES:
        cmds = _sub_commands(module)
        assert cmds, f"{module.__name__}.add_parser added no command"
        for name, parser in cmds.items():
            assert name not in seen, f"{name!r} added by {module.__name__} and {seen[name]}"
            seen[name] = module.__name__
            func = parser.get_default("func")
            if name in ("mission", "mavlink", "bench", "plugins", "train", "label"):  # a group: its own sub-commands
                continue
            assert func is not None and func.__module__ == module.__name__, (name, func, module.__name__)
    # the command line is exactly these modules' commands
    usage = cli.build_parser().format_usage()  # "usage: aerodaas [-h] {run,up,...} ..."
    top = usage[usage.index("{") + 1:usage.index("}")].split(",")
    assert set(top) == set(seen), (top, seen)


def test_cli_module_defines_no_command_of_its_own():
    tree = ast.parse((ROOT / "aerodaas" / "cli.py").read_text(encoding="utf-8"))
    names = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert names == {"console", "build_parser", "main"}, names


def test_a_command_runs_through_its_module(capsys):
    """``aerodaas schema`` (schema.py) prints the environment's JSON Schema, exit 0; a bad ``--cpus`` of ``up``
    (cluster.py) is refused with exit 2 naming the flag, before anything starts."""
    assert cli.main(["schema"]) == 0
    assert '"$defs"' in capsys.readouterr().out
    assert cli.main(["up", "--cpus", "0"]) == 2
    assert "--cpus must be in [1, 256], got 0" in capsys.readouterr().err
