"""Package names that load their module on first use.

A package such as :mod:`aptkt.learning` offers its main classes at its top level, but the command
line imports only the settings of it to build its parsers; loading every module there would load
scikit-learn and SciPy's statistics (about a second) before ``--help`` or a simulated data set.
So the package lists its names once, as imports under ``if TYPE_CHECKING:`` (what type checkers,
editors and the documentation read), and :func:`lazy_exports` reads that block to resolve each
name from its module on first access.
"""

from __future__ import annotations

import ast
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["lazy_exports"]


def _type_checking_imports(init_file: str) -> dict[str, str]:
    """name -> module of every ``from M import name`` in the file's ``if TYPE_CHECKING:``."""
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"))
    exports: dict[str, str] = {}
    for node in tree.body:
        if (
            isinstance(node, ast.If)
            and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING"
        ):
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom) and stmt.module and stmt.level == 0:
                    for alias in stmt.names:
                        exports[alias.asname or alias.name] = stmt.module
    return exports


def lazy_exports(
    package: str, init_file: str
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` (whose ``__init__`` is
    ``init_file``): a name imported under its ``if TYPE_CHECKING:`` is imported from its module
    when first asked for, then kept in the package."""
    exports = _type_checking_imports(init_file)

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
