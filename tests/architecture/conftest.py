"""The architecture checks' parse cache (:mod:`tests.architecture.sources`, about 200 MB of trees and text) is kept
while this folder's tests run one after the other (under ``--dist loadgroup`` they share one lane,
``tests/conftest.py`` :data:`~tests.conftest.ARCHITECTURE_LANE`, so one pytest worker parses the code base once) and
let go after the last of them, so the worker does not carry it into the Ray tests it runs next."""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.architecture import sources

HERE = Path(__file__).resolve().parent


@pytest.hookimpl(trylast=True)
def pytest_runtest_teardown(item, nextitem):
    if nextitem is None or Path(nextitem.path).resolve().parent != HERE:
        sources.tree.cache_clear()
        sources.source.cache_clear()
