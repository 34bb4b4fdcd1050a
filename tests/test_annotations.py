"""Public functions and methods carry type annotations (issue 9: py.typed is shipped).

For each module in MODULES, every public function defined in it (name not starting with ``_``)
and every public method, property and ``__init__`` of the public classes defined in it must
annotate each parameter (``self``/``cls``, ``*args`` and ``**kwargs`` excepted) and its return
(``__init__`` excepted). Names imported from elsewhere are the other module's business.

Add a module to MODULES once its public API is annotated.
"""
from __future__ import annotations

import importlib
import inspect
import types
from collections.abc import Callable, Iterator

import pytest

from conftest import require
from lavendersim import MissingExtraError

MODULES = (
    "lavendersim.validate",
    "lavendersim.control",
    "lavendersim.viewer",
    "lavendersim.oracle",
    "lavendersim.particles",
    "lavendersim.bodies",
    "lavendersim.envs.reaction_wheel_cube",
)

_VARIADIC = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)


def _public(name: str) -> bool:
    return not name.startswith("_") or name == "__init__"


def _defined_in(obj: object, module: str) -> bool:
    return getattr(obj, "__module__", None) == module


def _callables(mod: types.ModuleType) -> Iterator[tuple[str, Callable, bool]]:
    """(qualified name, function, is_method) for the public functions and methods defined in mod."""
    name = mod.__name__
    for attr, obj in sorted(vars(mod).items()):
        if not _public(attr) or not _defined_in(obj, name):
            continue
        if inspect.isfunction(obj):
            yield attr, obj, False
        elif inspect.isclass(obj):
            for member, raw in vars(obj).items():          # the class's own members, not inherited ones
                if not _public(member):
                    continue
                if isinstance(raw, property):
                    for part, fn in (("", raw.fget), (".setter", raw.fset), (".deleter", raw.fdel)):
                        if fn is not None:
                            yield f"{attr}.{member}{part}", fn, True
                    continue
                fn = raw.__func__ if isinstance(raw, (staticmethod, classmethod)) else raw
                if inspect.isfunction(fn):
                    # a dataclass's generated __init__ counts: its annotations are the field types
                    yield f"{attr}.{member}", fn, not isinstance(raw, staticmethod)


def missing_annotations(mod: types.ModuleType) -> list[str]:
    """One line per unannotated parameter or return among mod's public callables."""
    problems = []
    for qualname, fn, is_method in _callables(mod):
        sig = inspect.signature(fn)
        params = list(sig.parameters.values())
        if is_method and params and params[0].kind is not inspect.Parameter.KEYWORD_ONLY:
            params = params[1:]                            # self / cls
        for p in params:
            if p.kind not in _VARIADIC and p.annotation is inspect.Parameter.empty:
                problems.append(f"{mod.__name__}.{qualname}: parameter {p.name!r} has no annotation")
        if fn.__name__ != "__init__" and sig.return_annotation is inspect.Signature.empty:
            problems.append(f"{mod.__name__}.{qualname}: no return annotation")
    return problems


@pytest.mark.parametrize("module", MODULES)
def test_public_callables_are_annotated(module: str) -> None:
    try:
        mod = importlib.import_module(module)
    except MissingExtraError as exc:   # skipped outside CI, failed under CI=true (tests/conftest.py)
        require({"bench": "mujoco"}.get(exc.extra, exc.extra))
        raise
    problems = missing_annotations(mod)
    assert not problems, f"{len(problems)} missing annotation(s):\n" + "\n".join(problems)


def test_the_check_finds_what_is_missing() -> None:
    """The walker itself: it reports unannotated parameters and returns, skips self/cls, *args,
    **kwargs, private names, __init__'s return and names imported from another module."""
    src = '''
from os.path import join
def good(a: int, *args, b: str = "", **kw) -> None: ...
def bad(a, b: int): ...
def _private(a): ...
class C:
    def __init__(self, x): ...
    def m(self, y: int): ...
    @classmethod
    def c(cls, z) -> "C": ...
    @staticmethod
    def s(w) -> int: ...
    p = property(lambda self: 1)
    def _hidden(self, v): ...
class _P:
    def m(self, y): ...
'''
    mod = types.ModuleType("fake_annotations_module")
    exec(compile(src, "<fake>", "exec"), mod.__dict__)
    found = sorted(missing_annotations(mod))
    prefix = "fake_annotations_module."
    assert found == sorted(prefix + s for s in [
        "bad: parameter 'a' has no annotation",
        "bad: no return annotation",
        "C.__init__: parameter 'x' has no annotation",
        "C.m: no return annotation",
        "C.c: parameter 'z' has no annotation",
        "C.s: parameter 'w' has no annotation",
        "C.p: no return annotation",
    ]), found
