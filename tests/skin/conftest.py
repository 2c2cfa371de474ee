from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

# The test modules import their helpers by name (``skin_helpers``); with pytest's importlib
# import mode the test directory is not on sys.path by itself.
sys.path.insert(0, str(Path(__file__).parent))

from skin_helpers import VirtualAdapter  # noqa: E402


@pytest.fixture
def adapter() -> Iterator[VirtualAdapter]:
    a = VirtualAdapter()
    yield a
    a.close()
