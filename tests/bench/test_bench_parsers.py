"""The benchmarks' options are parsed without their code: ``aerodaas`` builds every ``bench``
sub-parser from :mod:`aerodaas.bench.parsers`, which imports a benchmark's module only when that benchmark runs.
Checked from ``sys.modules`` of a fresh interpreter (what Python itself loaded) and by running each benchmark with
a bad option in-process: its handler reaches the benchmark's ``main``, which refuses the option (exit 2, named)
before anything starts."""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from aerodaas import cli
from aerodaas.bench.options import FRAME_META_SOURCES
from tests.architecture.test_lazy_imports import HEAVY


def test_the_command_line_imports_no_benchmark_and_no_heavy_library():
    """Building the whole ``aerodaas`` parser (what ``aerodaas --help`` does: every command's ``add_parser``)
    imports, of ``aerodaas.bench``, only the parsers, their options and the report output, and none of the heavy
    libraries of ``tests/architecture/test_lazy_imports.py`` (NumPy, Ray, pydantic, the plug-in registry's ...):
    each command imports its handler's module when it runs."""
    code = textwrap.dedent(f"""
        import sys
        from aerodaas import cli
        cli.build_parser()
        print(" ".join(sorted(m for m in sys.modules if m.startswith("aerodaas.bench"))))
        print(" ".join(m for m in {HEAVY!r} if m in sys.modules))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    bench, heavy = (r.stdout + "\n").split("\n")[:2]
    assert heavy.split() == []
    assert set(bench.split()) == {"aerodaas.bench", "aerodaas.bench.options", "aerodaas.bench.output",
                                     "aerodaas.bench.parsers", "aerodaas.bench.schedulers_cli"}


@pytest.mark.parametrize("argv, message", [
    (["fleet", "--duration", "0"], "--duration must be > 0"),
    (["overhead", "--stub-ms", "-1"], "--stub-ms must be >= 0"),
    (["overhead", "--settle", "-1"], "--settle must be >= 0 seconds, got -1.0"),
    (["raypath", "--repeat", "0"], "--repeat must be >= 1"),
    (["recorder", "--fps", "0"], "--fps must be positive"),
    (["startup", "--app", "/nonexistent/app.py"], "application '/nonexistent/app.py' not found"),
    (["detect", "--images", ".", "--annotations", ".", "--thresholds", "2"], "--thresholds must be within [0, 1]"),
    (["video", "--readers", "nosuchreader"], "unknown reader/size ['nosuchreader']"),
    (["schedulers", "--harness", "--cloud-nodes", "2"], "--cloud-nodes: not used by --harness"),
])
def test_a_benchmark_refuses_a_bad_option_through_its_lazy_handler(argv, message, capfd):
    assert cli.main(["bench", *argv]) == 2
    assert message in capfd.readouterr().err


def test_a_plugin_kind_is_checked_when_given(capsys):
    """``aerodaas plugins --kind`` is checked against the registry's kinds only when given (the parser does not
    import the registry): an unknown kind exits 2 naming it and the kinds."""
    from aerodaas.plugins.registry import KINDS

    with pytest.raises(SystemExit) as e:
        cli.main(["plugins", "--kind", "nosuchkind"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "'nosuchkind'" in err and all(k in err for k in KINDS)


def test_the_detect_parser_offers_the_breakdown_frame_meta_sources():
    """:data:`aerodaas.bench.options.FRAME_META_SOURCES` is a light copy of the breakdown's own tuple."""
    from aerodaas.perception.breakdown import FRAME_META_SOURCES as BREAKDOWN_SOURCES

    assert FRAME_META_SOURCES == BREAKDOWN_SOURCES
