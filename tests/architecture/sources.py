"""The repository's Python files read and parsed once per test process: the architecture checks walk the same few
hundred files (imports, layers, function and module lengths, re-exports), and parsing them was most of their time."""
from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.lru_cache(maxsize=None)
def source(path: Path) -> str:
    """The file's text (UTF-8)."""
    return path.read_text(encoding="utf-8")


@functools.lru_cache(maxsize=None)
def tree(path: Path) -> ast.Module:
    """The file's syntax tree, shared by every caller: read it, never change it. Raises SyntaxError for a file
    Python cannot parse."""
    return ast.parse(source(path), str(path))
