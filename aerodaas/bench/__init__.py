"""Benchmarks behind ``aerodaas bench <name>``.

Each benchmark is a module here with a ``main(args) -> exit code``; their options are in
:mod:`aerodaas.bench.parsers` (light: what every ``aerodaas`` start imports), which imports a benchmark's module
only when it runs. Where a benchmark ran is :func:`aerodaas.bench.machine.machine_info`; its report goes to
standard output through :mod:`aerodaas.bench.output`. This package imports nothing itself.
"""
