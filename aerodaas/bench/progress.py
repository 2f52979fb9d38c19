"""A rich progress bar for benchmarks that run longer than ~10 s, drawn on stderr (stdout stays the JSON report)."""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["bench_progress"]


@contextmanager
def bench_progress(description: str, total: float) -> Iterator[tuple[Any, Any]]:
    """``with bench_progress("bench fleet", total=n) as (progress, task): ... progress.advance(task)``; lines printed
    with ``progress.console.print`` appear above the bar. On a non-terminal stderr rich prints no bar."""
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=Console(stderr=True)) as progress:
        yield progress, progress.add_task(description, total=total)
