"""Tests: bad input refused before Ray: applications, environment files, command lines, parsers."""
