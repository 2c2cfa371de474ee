from __future__ import annotations

from collections.abc import Iterator

import pytest
from skin_helpers import VirtualAdapter


@pytest.fixture
def adapter() -> Iterator[VirtualAdapter]:
    a = VirtualAdapter()
    yield a
    a.close()
