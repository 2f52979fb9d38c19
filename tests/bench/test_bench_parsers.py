"""The benchmarks' options are parsed without their code (issue 48 item 4): ``aerodaas`` builds every ``bench``
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


def test_the_command_line_imports_no_benchmark():
    """Building the whole ``aerodaas`` parser (what ``aerodaas --help`` does) imports, of ``aerodaas.bench``, only
    the parsers, their options and the report output, and neither NumPy nor Ray through them."""
    code = textwrap.dedent("""
        import sys
        from aerodaas import cli
        cli.build_parser()
        print(" ".join(sorted(m for m in sys.modules if m.startswith("aerodaas.bench"))))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert set(r.stdout.split()) == {"aerodaas.bench", "aerodaas.bench.options", "aerodaas.bench.output",
                                     "aerodaas.bench.parsers", "aerodaas.bench.schedulers_cli"}


@pytest.mark.parametrize("argv, message", [
    (["fleet", "--duration", "0"], "--duration must be > 0"),
    (["overhead", "--stub-ms", "-1"], "--stub-ms must be >= 0"),
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


def test_the_detect_parser_offers_the_breakdown_frame_meta_sources():
    """:data:`aerodaas.bench.options.FRAME_META_SOURCES` is a light copy of the breakdown's own tuple."""
    from aerodaas.perception.breakdown import FRAME_META_SOURCES as BREAKDOWN_SOURCES

    assert FRAME_META_SOURCES == BREAKDOWN_SOURCES
