"""Helpers for the tests of ``.npz`` files read defensively (prior knowledge, saved models):
members that declare more than they hold, and which members a read opened."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

__all__ = ["npy_header", "opened_members"]


def npy_header(shape: tuple[int, ...], dtype: str = "<f8") -> bytes:
    """A .npy member that declares ``shape`` but holds only a few bytes of data."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": dtype, "fortran_order": False, "shape": shape}
    )
    return buf.getvalue() + b"\0" * 64


def opened_members(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the zip members opened from now on (the list fills as they are)."""
    opened: list[str] = []
    original = zipfile.ZipFile.open

    def spy(self, name, *args, **kwargs):
        opened.append(name if isinstance(name, str) else name.filename)
        return original(self, name, *args, **kwargs)

    monkeypatch.setattr(zipfile.ZipFile, "open", spy)
    return opened
