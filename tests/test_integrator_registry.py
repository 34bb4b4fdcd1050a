"""The integrators are declared once (derive/tableaux.py INTEGRATORS) and printed for C and Python (issue 29).

Nothing else lists them: an AST scan of the hand-written Python (lavendersim/, labs/) finds no literal tuple,
list, set or dict holding two or more integrator names; the C module's constants, the backends' tables, the
accuracy lab's expected orders and the validity/decay bounds all come from the registry.
"""
import ast
from pathlib import Path

from lavendersim.derive import tableaux as T
from lavendersim import backends
from lavendersim.backends import c_backend
from lavendersim.generated import tableaux as TABLEAUX

ROOT = Path(__file__).resolve().parents[1]
NAMES = {i.name for i in T.INTEGRATORS}


def test_the_printed_registry_is_the_declaration():
    assert TABLEAUX.INTEGRATOR_CODES == {i.name: i.code for i in T.INTEGRATORS}
    assert list(backends.INTEGRATORS) == [i.name for i in T.INTEGRATORS]
    assert backends.ADAPTIVE == tuple(i.name for i in T.INTEGRATORS if i.adaptive)
    assert backends.PLAIN_ONLY == tuple(i.name for i in T.INTEGRATORS if i.plain_only)
    assert backends.FLOAT32_INTEGRATORS == tuple(i.name for i in T.INTEGRATORS if i.float32)
    assert c_backend.INTEGRATOR_CODES == TABLEAUX.INTEGRATOR_CODES
    for i in T.INTEGRATORS:          # the C module's constants come from tableaux.h's LV_INTEGRATORS
        assert getattr(c_backend._c, i.name.upper()) == i.code
    assert set(TABLEAUX.WDT_MAX) == {i.name for i in T.INTEGRATORS if not i.adaptive}
    assert set(TABLEAUX.REAL_AXIS_STABILITY) == NAMES


def test_the_c_status_codes_are_printed():
    h = (ROOT / "generated" / "tableaux.h").read_text(encoding="utf-8")
    for name, code, _ in T.STATUS:
        assert f"LV_{name} = {code}" in h
    step_h = (ROOT / "lavendersim" / "csrc" / "step.h").read_text(encoding="utf-8")
    assert "LV_INTEGRATOR_EULER = " not in step_h and "LV_OK = " not in step_h


def _literal_lists(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        items = None
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            items = node.elts
        elif isinstance(node, ast.Dict):
            items = [k for k in node.keys if k is not None]
        if items is None:
            continue
        named = [e.value for e in items if isinstance(e, ast.Constant) and e.value in NAMES]
        if len(named) >= 2:
            yield node.lineno, named


def test_no_hand_written_list_of_integrators():
    found = []
    for folder in ("lavendersim", "labs"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if "generated" in path.parts:
                continue
            found += [f"{path.relative_to(ROOT)}:{line}: {names}" for line, names in _literal_lists(path)]
    assert not found, "integrator names listed by hand (use lavendersim.generated.tableaux):\n" + "\n".join(found)


def test_the_accuracy_lab_never_calls_a_raising_integrator_unavailable(monkeypatch):
    from lavendersim.labs import accuracy

    real = accuracy._make_sim

    def make(case, m, value):
        if m.integrator == "splitting" and m.backend == "numpy":
            raise RuntimeError("broken on purpose")
        return real(case, m, value)

    monkeypatch.setattr(accuracy, "_make_sim", make)
    meths, broken = accuracy.methods(False)
    assert broken == {"splitting [numpy]": "RuntimeError: broken on purpose"}
    assert "splitting [numpy]" not in [m.label for m in meths]
    # every other registered integrator is measured on both backends
    assert {m.label for m in meths if m.family == "lavendersim" and m.dtype == "float64"} == {
        f"{n} [{b}]" for n in backends.INTEGRATORS for b in ("c", "numpy")} - {"splitting [numpy]"}
    src = Path(accuracy.__file__).read_text(encoding="utf-8")
    assert '(f"runs_{_key(label)}", False, "holds", None, why) for label, why in broken.items()' in src
