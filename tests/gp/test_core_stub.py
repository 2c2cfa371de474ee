"""The hand-written stub ``aptkt/_core.pyi`` against the compiled extension.

Every function, class, method, property, attribute and constant the stub declares must exist in
``aptkt._core`` with the same parameters (names, kinds, defaults), and every public name of the
compiled module and of its classes must be declared in the stub. A binding change that does not
update the stub fails here.
"""

from __future__ import annotations

import ast
import builtins
import inspect
from pathlib import Path

import pytest

from aptkt import _core

STUB = Path(_core.__file__).with_name("_core.pyi")
MODULE_DUNDERS = {"__doc__", "__file__", "__loader__", "__name__", "__package__", "__spec__"}
MODULE_DUNDERS |= {"__all__", "__path__", "__builtins__", "__cached__"}


def _stub() -> ast.Module:
    return ast.parse(STUB.read_text())


def _public(names) -> set[str]:
    return {n for n in names if not (n.startswith("__") and n.endswith("__"))}


def _stub_params(fn: ast.FunctionDef, method: bool) -> list[tuple[str, str, object]]:
    """(name, kind, default) per parameter; default is ``inspect.Parameter.empty`` if none."""
    args = fn.args
    out: list[tuple[str, str, object]] = []
    positional = args.posonlyargs + args.args
    defaults = [inspect.Parameter.empty] * (len(positional) - len(args.defaults))
    defaults += [ast.literal_eval(d) for d in args.defaults]
    for i, (arg, default) in enumerate(zip(positional, defaults)):
        kind = "POSITIONAL_ONLY" if i < len(args.posonlyargs) else "POSITIONAL_OR_KEYWORD"
        out.append((arg.arg, kind, default))
    if args.vararg:
        out.append((args.vararg.arg, "VAR_POSITIONAL", inspect.Parameter.empty))
    for arg, default in zip(args.kwonlyargs, args.kw_defaults):
        value = inspect.Parameter.empty if default is None else ast.literal_eval(default)
        out.append((arg.arg, "KEYWORD_ONLY", value))
    if args.kwarg:
        out.append((args.kwarg.arg, "VAR_KEYWORD", inspect.Parameter.empty))
    if method:
        out = out[1:]  # self
    return out


def _compiled_params(obj, method: bool) -> list[tuple[str, str, object]]:
    params = list(inspect.signature(obj).parameters.values())
    if method and params and params[0].name in ("self", "$self"):
        params = params[1:]
    return [(p.name, p.kind.name, p.default) for p in params]


def _same_params(stub, compiled) -> bool:
    if len(stub) != len(compiled):
        return False
    for (sn, sk, sd), (cn, ck, cd) in zip(stub, compiled):
        # The binding's own "self, /" is positional-only; the stub writes plain names.
        kinds_match = sk == ck or {sk, ck} == {"POSITIONAL_ONLY", "POSITIONAL_OR_KEYWORD"}
        if sn != cn or not kinds_match:
            return False
        if (sd is inspect.Parameter.empty) != (cd is inspect.Parameter.empty):
            return False
        # Text signatures render non-literal defaults (tuples, strings built in Rust) as "...".
        if cd is not inspect.Parameter.empty and cd is not Ellipsis and sd != cd:
            return False
    return True


def _is_property(fn: ast.FunctionDef) -> bool:
    return _decorated(fn, "property")


def _decorated(fn: ast.FunctionDef, name: str) -> bool:
    return any(isinstance(d, ast.Name) and d.id == name for d in fn.decorator_list)


def _declared_members(cls: ast.ClassDef) -> dict[str, ast.AST]:
    members: dict[str, ast.AST] = {}
    for node in cls.body:
        if isinstance(node, ast.FunctionDef):
            members[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            members[node.target.id] = node
    return members


def _top_level() -> dict[str, ast.AST]:
    out: dict[str, ast.AST] = {}
    for node in _stub().body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out[node.target.id] = node
    return out


def test_every_compiled_name_is_declared_and_vice_versa():
    declared = _top_level()
    compiled = _public(dir(_core)) | ({"__version__"} & set(dir(_core)))
    compiled -= MODULE_DUNDERS
    assert sorted(compiled - set(declared)) == [], "in _core but missing from _core.pyi"
    assert sorted(set(declared) - compiled) == [], "declared in _core.pyi but not in _core"


@pytest.mark.parametrize(
    "name", [n for n, node in _top_level().items() if isinstance(node, ast.FunctionDef)]
)
def test_function_signatures_match(name):
    node = _top_level()[name]
    assert _same_params(
        _stub_params(node, method=False), _compiled_params(getattr(_core, name), method=False)
    ), (
        f"{name}: stub {ast.unparse(node.args)} vs compiled {inspect.signature(getattr(_core, name))}"
    )


@pytest.mark.parametrize(
    "name", [n for n, node in _top_level().items() if isinstance(node, ast.AnnAssign)]
)
def test_constants_have_the_declared_type(name):
    node = _top_level()[name]
    annotation = node.annotation
    base = annotation.value if isinstance(annotation, ast.Subscript) else annotation
    assert isinstance(base, ast.Name), f"{name}: annotation too complex to check"
    assert isinstance(getattr(_core, name), getattr(builtins, base.id))


@pytest.mark.parametrize(
    "name", [n for n, node in _top_level().items() if isinstance(node, ast.ClassDef)]
)
def test_classes_match(name):
    node = _top_level()[name]
    cls = getattr(_core, name)
    assert isinstance(cls, type), f"{name} is not a class in _core"
    for base in node.bases:
        base_name = ast.unparse(base)
        base_cls = getattr(_core, base_name, None) or getattr(builtins, base_name)
        assert issubclass(cls, base_cls), f"{name} should derive from {base_name}"
    if issubclass(cls, BaseException):
        return
    declared = _declared_members(node)
    compiled = _public(vars(cls))
    assert sorted(compiled - set(declared)) == [], f"{name}: members missing from the stub"
    assert sorted(_public(declared) - compiled) == [], f"{name}: stub members not compiled"
    for member, decl in declared.items():
        if member == "__init__":
            assert _same_params(
                _stub_params(decl, method=True), _compiled_params(cls, method=False)
            ), f"{name}.__init__: stub vs compiled {inspect.signature(cls)}"
            continue
        if member.startswith("__"):
            continue
        attr = vars(cls)[member]
        is_data = isinstance(decl, ast.AnnAssign) or _is_property(decl)
        # A field read straight from the object (a pyclass's `Py<...>`) is a member descriptor.
        compiled_data = inspect.isgetsetdescriptor(attr) or inspect.ismemberdescriptor(attr)
        assert compiled_data == is_data, f"{name}.{member}: kind differs"
        if not is_data:
            static = _decorated(decl, "staticmethod")
            assert static == isinstance(attr, staticmethod), f"{name}.{member}: static differs"
            assert _same_params(
                _stub_params(decl, method=not static), _compiled_params(attr, method=not static)
            ), f"{name}.{member}: stub vs compiled {inspect.signature(attr)}"
    if "__init__" not in declared:
        assert _compiled_params(cls, method=False) == [], f"{name}: constructor not declared"
