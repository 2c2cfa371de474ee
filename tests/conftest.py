"""Test helpers shared by several areas live in ``tests/helpers`` and are imported by name
(``from loopback_helpers import ...``); with pytest's importlib import mode no test directory
is on sys.path by itself."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "helpers"))
