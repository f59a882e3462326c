from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support import router_process


@pytest.fixture
def router(tmp_path: Path) -> Iterator[str]:
    """A Zenoh router process on a free loopback port; yields its endpoint."""
    with router_process(tmp_path) as endpoint:
        yield endpoint
