"""One way to add a command: every ``aerodaas`` sub-command comes from a module of
:data:`aerodaas.commands.COMMAND_MODULES` that holds both its parser and its handler; ``aerodaas/cli.py`` only
assembles them. One shape for that module (the rule in ``aerodaas/commands/__init__.py`` and
``docs/architecture.md``): ``aerodaas/commands/NAME.py`` with ``add_parser(sub)``, no ``*_main.py`` beside it, and
handlers named ``run`` or ``run_<sub-command>``, defined in the module that sets them; ``bench`` is the one group
whose sub-commands (the benchmarks) register themselves in :mod:`aerodaas.bench.parsers`."""
from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

from aerodaas import cli
from aerodaas.commands import COMMAND_MODULES

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = ROOT / "aerodaas" / "commands"
#: a handler's name: ``run`` (a single command) or ``run_<sub-command>``
HANDLER_NAME = re.compile(r"run(_[a-z][a-z0-9_]*)?")
#: the group whose sub-commands register themselves elsewhere (:func:`aerodaas.bench.parsers.add_parsers`)
SELF_REGISTERING = {"bench"}


def _sub_commands(module) -> dict[str, argparse.ArgumentParser]:
    """The sub-parsers ``module.add_parser`` adds to a fresh sub-parsers action, by command name."""
    sub = argparse.ArgumentParser(prog="t").add_subparsers(dest="cmd")
    module.add_parser(sub)
    return dict(sub.choices)


def _handlers(name: str, parser: argparse.ArgumentParser):
    """(command path, handler) of ``parser`` and, through its sub-parsers, of every sub-command below it: the
    commands a user can run (a group without a handler of its own is not one)."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subs:
        yield name, parser.get_default("func")
    for action in subs:
        for sub_name, sub_parser in action.choices.items():
            yield from _handlers(f"{name} {sub_name}", sub_parser)


def test_each_command_module_adds_commands_whose_handler_it_holds():
    seen: dict[str, str] = {}
    for module in COMMAND_MODULES:
        cmds = _sub_commands(module)
        assert cmds, f"{module.__name__}.add_parser added no command"
        for name, parser in cmds.items():
            assert name not in seen, f"{name!r} added by {module.__name__} and {seen[name]}"
            seen[name] = module.__name__
            if name in SELF_REGISTERING:
                continue
            for path, func in _handlers(name, parser):
                assert func is not None and getattr(func, "__module__", None) == module.__name__, (
                    f"aerodaas {path}: its handler {func!r} is not defined in {module.__name__}")
                assert HANDLER_NAME.fullmatch(func.__name__), (
                    f"aerodaas {path}: handler {module.__name__}.{func.__name__} is named neither run nor run_<sub-command>")
    # the command line is exactly these modules' commands
    usage = cli.build_parser().format_usage()  # "usage: aerodaas [-h] {run,up,...} ..."
    top = usage[usage.index("{") + 1:usage.index("}")].split(",")
    assert set(top) == set(seen), (top, seen)


def shape_problems(commands: Path = COMMANDS) -> list[str]:
    """What in the folder ``commands`` breaks the one shape of a command module: a ``*_main.py`` file; a module
    that is not listed in ``COMMAND_MODULES`` or has no top-level ``add_parser``; a ``set_defaults(func=...)``
    whose handler is not a name ``run``/``run_*`` defined at the top of the same module. Read with :mod:`ast`, so a
    file that would not import is judged too."""
    listed = {m.__name__.rsplit(".", 1)[1] for m in COMMAND_MODULES}
    out = []
    for f in sorted(commands.glob("*.py")):
        if f.name == "__init__.py":
            continue
        if f.stem.endswith("_main"):
            out.append(f"{f.name}: a *_main.py module; the work goes to its concept package, the argument handling "
                       f"to {f.stem[:-5]}.py")
            continue
        tree = ast.parse(f.read_text(encoding="utf-8"))
        defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
        if "add_parser" not in defined:
            out.append(f"{f.name}: no add_parser(sub)")
        if f.stem not in listed:
            out.append(f"{f.name}: not in COMMAND_MODULES (one module per command; a helper goes into the command's "
                       f"module or its concept package)")
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "set_defaults"):
                continue
            for kw in node.keywords:
                if kw.arg != "func":
                    continue
                name = kw.value.id if isinstance(kw.value, ast.Name) else ast.unparse(kw.value)
                if not (isinstance(kw.value, ast.Name) and HANDLER_NAME.fullmatch(name) and name in defined):
                    out.append(f"{f.name}:{node.lineno}: set_defaults(func={name}): a handler is a function of this "
                               f"module named run or run_<sub-command>")
    return out


def test_every_command_module_has_the_one_shape():
    problems = shape_problems()
    assert not problems, "\n".join(problems)


def test_the_shape_check_finds_each_break(tmp_path):
    """The check itself fails on a ``*_main.py``, a module without ``add_parser`` and a handler of another name."""
    for f in COMMANDS.glob("*.py"):
        (tmp_path / f.name).write_text(f.read_text(encoding="utf-8"), encoding="utf-8")
    assert shape_problems(tmp_path) == []
    (tmp_path / "run_main.py").write_text("def run(args):\n    return 0\n")
    info = tmp_path / "info.py"
    info.write_text(info.read_text().replace("def add_parser(", "def add_parsers("))
    plan = tmp_path / "plan.py"
    plan.write_text(plan.read_text().replace("set_defaults(func=run)", "set_defaults(func=cmd_plan)"))
    problems = "\n".join(shape_problems(tmp_path))
    assert "run_main.py: a *_main.py module" in problems, problems
    assert "info.py: no add_parser(sub)" in problems, problems
    assert "set_defaults(func=cmd_plan)" in problems, problems


def test_no_command_is_registered_outside_its_command_module():
    """A ``set_defaults(func=...)`` in production code is in ``aerodaas/commands/`` or is a benchmark's
    (``aerodaas/bench/``): no command module grows again beside the tools it drives."""
    outside = []
    for base in ("aerodaas", "actors", "schedulers", "clusters"):
        for f in sorted((ROOT / base).rglob("*.py")):
            rel = f.relative_to(ROOT).as_posix()
            if rel.startswith(("aerodaas/commands/", "aerodaas/bench/")):
                continue
            if re.search(r"set_defaults\(\s*func\s*=", f.read_text(encoding="utf-8")):
                outside.append(rel)
    assert not outside, f"sub-command handlers set outside aerodaas/commands/: {outside}"


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
