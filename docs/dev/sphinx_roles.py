"""A griffe extension for the API reference: the docstrings cross-reference with Sphinx roles
(:class:`~aptkt.gp.LaplaceGPC`), which mkdocstrings leaves as raw text. Each becomes a code
span, shortened as the ~ asks; a link would fail the strict build for targets outside the
reference."""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|exc|obj|const|term):`(~?)([^`]+)`")


def _span(match: re.Match[str]) -> str:
    target = match[2].strip()
    return f"`{target.rsplit('.', 1)[-1] if match[1] else target}`"


class SphinxRoles(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(_span, obj.docstring.value)
