"""The architecture checks' parse cache (:mod:`tests.architecture.sources`, about 130 MB of trees and text) is let go
after each module, so the pytest worker does not carry it into the Ray tests it runs next."""
from __future__ import annotations

import pytest

from tests.architecture import sources


@pytest.fixture(autouse=True, scope="module")
def _release_parsed_sources():
    yield
    sources.tree.cache_clear()
    sources.source.cache_clear()
