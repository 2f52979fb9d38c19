"""Tests: the extension points: the plug-in registry, the built-ins' contract, the example plug-in package."""
