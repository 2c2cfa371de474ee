"""The package's import graph: imports run only downwards through the layers, and no module
imports itself back through others (no cycles).

Layers, low to high (a room may import from its own room and from lower layers only; rooms
on one layer do not import each other, e.g. ``sim`` and ``learning`` stand side by side)::

    _core | errors | files, progress, names | skin, features, gp | robot, data | actions
    | sim, learning | runtime, importers | experiments | commands, cli | _entry, reference

Imports under ``if TYPE_CHECKING:`` are for annotations only and are not counted for the layers
(except in a package whose names load on first use, ``aptkt._lazy``: there they are the package's
real, deferred imports); for cycles they are (two modules that name each other cannot be read apart). Imports inside
functions are counted for both: they are real dependencies, only deferred. The package root (``aptkt``,
which re-exports the core's version) counts as the bottom layer.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "aptkt"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("_core",),  # the compiled core (it raises the classes of aptkt.errors, fetched when raised)
    ("", "errors", "_lazy"),
    # files from elsewhere (regular, bounded, checked); progress lines; what a name may be
    ("files", "progress", "names"),
    ("skin", "features", "gp"),
    ("robot", "data"),
    ("actions",),
    ("sim", "learning"),
    ("runtime", "importers"),
    ("experiments",),
    ("commands", "cli"),
    # the console script (signals while it starts, then the cli); the command-line reference
    # page, generated from the parsers
    ("_entry", "reference"),
)
LAYER_OF = {room: i for i, rooms in enumerate(LAYERS) for room in rooms}


def module_name(path: Path) -> str:
    parts = ["aptkt", *path.relative_to(PACKAGE).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_of(path: Path, *, annotations: bool = False) -> list[tuple[str, int]]:
    """``(imported aptkt module, line)`` for every import of the file that runs; with
    ``annotations`` also those under ``if TYPE_CHECKING:``."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: list[tuple[str, int]] = []
    # A lazy package's TYPE_CHECKING block lists what it imports on first use.
    annotations = annotations or "lazy_exports(" in path.read_text(encoding="utf-8")

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test) and not annotations:
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.extend((a.name, node.lineno) for a in node.names if a.name.startswith("aptkt"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "aptkt" or target.startswith("aptkt."):
                for alias in node.names:
                    # `from aptkt.sim import world` imports the module aptkt.sim.world.
                    sub = f"{target}.{alias.name}"
                    found.append((sub if sub in MODULES else target, node.lineno))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return found


FILES = sorted(PACKAGE.rglob("*.py"))
MODULES = {module_name(p) for p in FILES} | {"aptkt._core"}
GRAPH = {module_name(p): imports_of(p) for p in FILES}


def test_every_room_has_a_layer():
    rooms = {room(m) for m in MODULES}
    assert rooms <= set(LAYER_OF), f"rooms without a layer: {sorted(rooms - set(LAYER_OF))}"


def test_imports_only_run_downwards():
    wrong = []
    for module, imports in GRAPH.items():
        here = room(module)
        for target, line in imports:
            there = room(target)
            if there != here and LAYER_OF[there] >= LAYER_OF[here]:
                wrong.append(f"{module}:{line} imports {target} ({here} -> {there})")
    assert not wrong, "imports against the layers:\n" + "\n".join(wrong)


def import_cycles(edges: dict[str, set[str]]) -> list[str]:
    """Every cycle a depth-first walk of ``edges`` (module -> modules it imports) closes, as
    ``a -> b -> a``."""
    cycles = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def walk(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(edges.get(m, ())):
            if state.get(t) == 1:
                cycles.append(" -> ".join([*stack[stack.index(t) :], t]))
            elif t not in state:
                walk(t)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            walk(m)
    return cycles


def module_edges(graph: dict[str, list[tuple[str, int]]]) -> dict[str, set[str]]:
    edges = {m: {t for t, _ in imps if t in graph and t != m} for m, imps in graph.items()}
    # A package's __init__ importing its own modules is how re-exports work; a module of the
    # package importing the package (its __init__) back is the cycle that matters.
    return {m: {t for t in ts if not m.startswith(t + ".")} for m, ts in edges.items()}


def test_no_module_imports_itself_back():
    cycles = import_cycles(module_edges(GRAPH))
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


#: Modules that name each other under ``if TYPE_CHECKING:`` only (annotations): not a cycle
#: when the package is imported, but two modules that cannot be read apart. None may be added;
#: each listed one must still be there (the test says when it is gone).
KNOWN_ANNOTATION_CYCLES: set[str] = set()


def test_no_modules_name_each_other_even_for_annotations():
    """Imports under ``if TYPE_CHECKING:`` counted too: such a pair (the loopback's controller
    and dashboard were one) is a circle in the design even if Python never runs it; the piece
    both need belongs below them (a Protocol, a shared module)."""
    graph = {module_name(p): imports_of(p, annotations=True) for p in FILES}
    cycles = set(import_cycles(module_edges(graph)))
    assert cycles - KNOWN_ANNOTATION_CYCLES == set(), "import cycles:\n" + "\n".join(
        sorted(cycles - KNOWN_ANNOTATION_CYCLES)
    )
    assert KNOWN_ANNOTATION_CYCLES <= cycles, "no longer a cycle: remove it from the list"


def test_every_module_imports():
    """Every module of the package imports (a cycle that runs at import time fails here as
    the ImportError of a partly initialised module)."""
    for name in sorted(MODULES - {"aptkt._core"}):
        importlib.import_module(name)


@pytest.mark.parametrize(
    ("edges", "expected"),
    [
        ({"a": {"b"}, "b": {"a"}}, ["a -> b -> a"]),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, ["a -> b -> c -> a"]),
        ({"a": {"b", "c"}, "b": {"c"}, "c": set()}, []),
    ],
    ids=["two modules", "three modules", "a diamond, no cycle"],
)
def test_the_cycle_checker_finds_a_cycle(edges, expected):
    # The checker itself: one that missed cycles would pass any package.
    assert import_cycles(edges) == expected


def test_the_cycle_checker_sees_a_cycle_made_of_annotations(monkeypatch):
    sources = {
        "a.py": "from aptkt.learning import b\n",
        "b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from aptkt.learning import a\n",
    }
    monkeypatch.setattr(Path, "read_text", lambda self, encoding=None: sources[self.name])
    modules = {"aptkt.learning.a", "aptkt.learning.b"}
    monkeypatch.setattr(sys.modules[__name__], "MODULES", MODULES | modules)
    files = [PACKAGE / "learning" / "a.py", PACKAGE / "learning" / "b.py"]
    strict = {module_name(f): imports_of(f, annotations=True) for f in files}
    loose = {module_name(f): imports_of(f) for f in files}
    assert import_cycles(module_edges(strict)) == [
        "aptkt.learning.a -> aptkt.learning.b -> aptkt.learning.a"
    ]
    assert import_cycles(module_edges(loose)) == []


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from aptkt.sim import world\n", ["aptkt.sim.world"]),
        ("from aptkt.errors import ConfigError\n", ["aptkt.errors"]),
        ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import aptkt.sim\n", []),
        ("def f():\n    from aptkt.runtime import sessions\n", ["aptkt.runtime.sessions"]),
    ],
)
def test_the_checker_reads_imports_as_python_does(tmp_path, source, expected, monkeypatch):
    # The checker itself: a checker that missed imports would pass anything.
    fake = PACKAGE / "learning" / "_layers_probe.py"
    monkeypatch.setattr(Path, "read_text", lambda self, encoding=None: source)
    assert [t for t, _ in imports_of(fake)] == expected
