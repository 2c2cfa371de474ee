"""Errors a Python user can catch: every error aptkt raises on purpose is an :class:`AptktError`
and also the builtin a user would catch for the same mistake (``except ValueError`` written
before the typed errors existed keeps working). Each case below is a real call that raises it,
through the Rust core where the core raises it, so a conversion in the binding that picks the
wrong class fails here.
"""

from __future__ import annotations

import ast
import builtins
from pathlib import Path

import numpy as np
import pytest

from aptkt import _core, errors, features
from aptkt.errors import (
    AptktError,
    IndexOutOfRangeError,
    InvalidInputError,
    InvalidStateError,
    InvalidTypeError,
    KernelNotPositiveDefiniteError,
    NonFiniteResultError,
    ProblemTooLargeError,
    UnknownNameError,
)

PACKAGE = Path(errors.__file__).resolve().parent


def _overflowing_hjorth() -> None:
    features.hjorth([1e308, -1e308] * 10)


def _kernel_matrix_too_large() -> None:
    # 200,000 rows: the n x n matrices need ~1 TB, refused before anything is allocated.
    _core.kernel_matrix(np.zeros((200_000, 1)), [0.0, 0.0], [[0]])


def _kernel_matrix_with_nan() -> None:
    _core.kernel_matrix(np.array([[0.0], [np.nan]]), [0.0, 0.0], [[0]])


def _feature_kernel_of_strings() -> None:
    _core.hjorth(np.array(["a", "b"]), 0)


def _sim_table_that_does_not_increase() -> None:
    _core.ContactLaw([0.0, 0.0], [0.0, 1.0], 1.0, [], [], 1.0)


def _skin_payload_outside_seven_bits() -> None:
    header = next(iter(_core.PACKET_TYPES.values()))
    _core.encode_packet_bytes(header, bytes([0x80] * 18))


def _ring_of_no_capacity() -> None:
    from aptkt.skin.ring import SampleRing

    SampleRing(0)


def _unknown_object() -> None:
    from aptkt.sim.objects import default_library

    default_library()["no such object"]


CASES = [
    pytest.param(_overflowing_hjorth, NonFiniteResultError, ValueError, id="core-overflow"),
    pytest.param(_kernel_matrix_too_large, ProblemTooLargeError, MemoryError, id="core-too-large"),
    pytest.param(_kernel_matrix_with_nan, InvalidInputError, ValueError, id="core-nan"),
    pytest.param(_feature_kernel_of_strings, InvalidTypeError, TypeError, id="core-dtype"),
    pytest.param(_sim_table_that_does_not_increase, InvalidInputError, ValueError, id="core-sim"),
    pytest.param(_skin_payload_outside_seven_bits, InvalidInputError, ValueError, id="core-skin"),
    pytest.param(_ring_of_no_capacity, InvalidInputError, ValueError, id="python-value"),
    pytest.param(_unknown_object, UnknownNameError, KeyError, id="python-name"),
]


@pytest.mark.parametrize(("call", "typed", "builtin"), CASES)
def test_each_typed_error_is_caught_as_its_builtin(call, typed, builtin):
    with pytest.raises(builtin) as info:
        call()
    assert type(info.value) is typed, f"{type(info.value).__name__}: {info.value}"
    assert isinstance(info.value, AptktError)


@pytest.mark.parametrize(
    ("typed", "builtin"),
    [
        (InvalidInputError, ValueError),
        (NonFiniteResultError, ValueError),
        (KernelNotPositiveDefiniteError, ValueError),
        (ProblemTooLargeError, MemoryError),
        (InvalidTypeError, TypeError),
        (UnknownNameError, KeyError),
        (IndexOutOfRangeError, IndexError),
        (InvalidStateError, RuntimeError),
    ],
)
def test_the_hierarchy_promised_in_the_docstrings(typed, builtin):
    assert issubclass(typed, AptktError) and issubclass(typed, builtin)


def test_a_name_error_reads_as_a_sentence_not_a_quoted_key():
    # KeyError's str() is the repr of its argument: quotes, and escaped quotes inside.
    message = "unknown action 'x'; known: press"
    assert str(UnknownNameError(message)) == message


def test_the_core_raises_the_classes_of_aptkt_errors():
    """The binding fetches its classes from aptkt.errors: one definition, not a twin in _core."""
    for name in ("AptktError", "NonFiniteResultError", "ProblemTooLargeError"):
        assert not hasattr(_core, name)
    with pytest.raises(errors.NonFiniteResultError):
        _overflowing_hjorth()


# Builtin exceptions raised on purpose that stay builtins, each with its reason. Keep it short:
# anything a user can cause belongs in aptkt.errors.
ALLOWED: dict[tuple[str, str], str] = {
    ("*", "NotImplementedError"): "abstract methods of base classes (a programming error)",
    ("data/codec.py", "TypeError"): "json's `default=` hook must raise TypeError",
    ("_lazy.py", "AttributeError"): "a module's __getattr__ must raise AttributeError (PEP 562)",
    ("__init__.py", "AttributeError"): "likewise: the package's version is looked up on first use",
    ("robot/ur10/_control_child.py", "RuntimeError"): (
        "the ur_rtde child process reports errors as ur_rtde raises them; the parent maps them"
    ),
    ("robot/ur10/control.py", "RuntimeError"): (
        "re-raises in the parent what ur_rtde raised in the child, so that the robot layer's "
        "handling of ur_rtde's errors applies unchanged (it raises RobotError)"
    ),
    ("robot/ur10/control.py", "TypeError"): "likewise, ur_rtde's TypeError for a wrong call",
    ("robot/ur10/control.py", "TimeoutError"): (
        "the handshake's timeout, caught where it is raised and turned into RobotConnectionError"
    ),
    ("sim/loopback/servers.py", "ConnectionError"): (
        "the simulated controller's socket closed by its peer: the OSError a real socket gives"
    ),
}

_BUILTIN_ERRORS = {
    name
    for name, value in vars(builtins).items()
    if isinstance(value, type) and issubclass(value, BaseException)
}


def _builtin_raises() -> list[tuple[str, int, str]]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE).as_posix()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if not isinstance(node, ast.Raise) or node.exc is None:
                continue
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(exc, ast.Name) and exc.id in _BUILTIN_ERRORS:
                found.append((where, node.lineno, exc.id))
    return found


def test_nothing_raised_on_purpose_is_a_bare_builtin():
    stray = [
        f"{where}:{line}: raise {name}"
        for where, line, name in _builtin_raises()
        if (where, name) not in ALLOWED and ("*", name) not in ALLOWED
    ]
    assert stray == [], "raise a class of aptkt.errors instead:\n" + "\n".join(stray)


def test_the_allow_list_has_no_stale_entries():
    used = {(where, name) for where, _, name in _builtin_raises()}
    used |= {("*", name) for _, name in used}
    assert sorted(set(ALLOWED) - used) == []
