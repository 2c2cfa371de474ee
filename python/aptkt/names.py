"""What a name of an object, an action or an extraction may be.

Names reach reports, plots, tables and one-line error messages. A control character (a
newline, a NUL, an escape) breaks a line in two, draws as a missing glyph or rewrites a
terminal; a name of thousands of characters stalls a plot's layout. Neither is a name anyone
gave an object: such a name is refused where it is read, in one line that shows it escaped.
"""

from __future__ import annotations

import unicodedata

__all__ = ["MAX_NAME_LENGTH", "name_problem"]

#: The longest name, in characters.
MAX_NAME_LENGTH = 200


def name_problem(name: str) -> str | None:
    """Why ``name`` is no name (None: it is one), shown escaped and shortened."""
    if len(name) > MAX_NAME_LENGTH:
        return f"a name of {len(name):,} characters (at most {MAX_NAME_LENGTH}): {name[:40]!r}..."
    bad = next((c for c in name if unicodedata.category(c) == "Cc"), None)
    if bad is not None:
        shown = name if len(name) <= 60 else name[:57] + "..."
        return f"a name with the control character {bad!r}: {shown!r}"
    return None
