"""Tests: the code base's shape: layers and import graph, module and function size, private reach, CLI commands."""
