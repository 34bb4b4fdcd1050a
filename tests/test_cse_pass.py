"""derive/cse_pass.py (issue 30): after CSE, negation temporaries fold into their uses and a product by a power of
two reuses the scaled temporary that exists — fewer operations, the same bits (every kernel derive prints)."""
from __future__ import annotations

import random
import re
import struct
from pathlib import Path

import sympy as sp

from lavendersim.derive.cse_pass import _power_of_two, late_factor_last, tidy
from lavendersim.derive.kernel import vec
from lavendersim.derive.quaternion import rotate_to_body

GENERATED = Path(__file__).resolve().parents[1] / "generated"
Q, C, P = vec("q", 4), vec("c", 3), vec("p", 3)


def _cse(exprs):
    return sp.cse(exprs, symbols=sp.numbered_symbols("t"), order="canonical")


def _negation_temps(temps):
    return [t for t, e in temps if e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and e.args[1].is_Symbol]


def _evaluate(temps, reduced, point: dict) -> list[float]:
    """The kernel's outputs as Python floats, each operation in the printed order (lambdify prints the tree)."""
    env = dict(point)
    for t, e in temps:
        env[t.name] = sp.lambdify(list(env), e, "math")(*env.values())
    return [float(sp.lambdify(list(env), e, "math")(*env.values())) for e in reduced]


def _bits(xs):
    return [struct.pack("<d", x) for x in xs]


def _gravity_gradient_like():
    """The guide's effect's arithmetic: r_b = R(q)ᵀ (c − p), its squared norm, and r_b's pairwise products."""
    r = rotate_to_body(Q, C - P)
    n2 = (C - P).dot(C - P)
    return [r[1] * r[2] / n2, r[0] * r[2] / n2, r[0] * r[1] / n2, -r[0]]


def test_the_pass_removes_cse_negations_and_shares_doubled_temporaries_bit_for_bit():
    exprs = _gravity_gradient_like()
    temps, reduced = _cse(exprs)
    assert _negation_temps(temps)                                     # the premise: CSE leaves `t2 = -t1`
    new_temps, new_reduced = tidy(temps, reduced)
    assert not _negation_temps(new_temps)
    assert len(new_temps) < len(temps)          # (count_ops counts a product's sign, which the C printing folds)
    rng = random.Random(3)
    names = sorted({s.name for e in exprs for s in e.free_symbols})
    for _ in range(200):
        point = {n: rng.choice([rng.uniform(-3, 3), rng.uniform(-1e-3, 1e-3), 1.0]) for n in names}
        old, new = _evaluate(temps, reduced, point), _evaluate(new_temps, new_reduced, point)
        assert _bits(old) == _bits(new), point
    # every output is still the function CSE was given
    back = [e.subs(list(reversed(new_temps))) for e in new_reduced]
    assert all(sp.expand(a - b) == 0 for a, b in zip(back, exprs))


def test_a_doubled_temporary_is_used_where_it_is_defined_later():
    a, b, f = sp.symbols("a b f")
    s0, s1 = sp.symbols("t0 t1")
    temps = [(s0, f + a), (s1, 2 * s0)]
    reduced = [2 * a * s0, -2 * b * s0, 3 * a * s0, 2 * a * b * s0]
    new_temps, new_reduced = tidy(temps, reduced)
    assert new_temps == temps
    assert new_reduced[:2] == [a * s1, -b * s1]
    assert new_reduced[2] == 3 * a * s0            # 3 is not a power of two: (3a)f is not a(3f) in floating point
    assert new_reduced[3] == 2 * a * b * s0        # three factors: the printer could reorder them
    early_temps, early_reduced = tidy([(s0, f + a), (sp.Symbol("t2"), 2 * a * s0), (s1, 2 * s0)], [s1])
    assert [t for t, _ in early_temps] == [s0, s1, sp.Symbol("t2")] and early_temps[2][1] == a * s1


def test_negations_fold_into_sums_products_and_squares():
    a, b, c = sp.symbols("a b c")
    t0, t1, t2 = sp.symbols("t0 t1 t2")
    temps = [(t0, a - b), (t1, -t0), (t2, -c)]
    new_temps, new_reduced = tidy(temps, [t1 * c, t1 ** 2, a - t2, t1 + t0 * c])
    assert new_temps == [(t0, a - b)]
    assert new_reduced == [-t0 * c, t0 ** 2, a + c, t0 * c - t0]


def test_power_of_two():
    assert all(_power_of_two(sp.Integer(k)) for k in (2, -2, 4, 1024))
    assert all(_power_of_two(sp.Rational(1, k)) for k in (2, -4, 8))
    assert not any(_power_of_two(sp.sympify(k)) for k in (1, -1, 0, 3, 6, sp.Rational(2, 3), sp.Rational(3, 4)))


def test_no_printed_kernel_keeps_a_negation_temporary():
    for name in ("kernels.c", "kernels_f32.c"):
        text = (GENERATED / name).read_text()
        assert not re.findall(r"const (?:double|float) t\d+ = -\w+;", text), name


def test_a_late_factor_is_multiplied_in_last():
    u, w, x = sp.symbols("u w x")
    t0, t1 = sp.symbols("t0 t1")
    temps = [(t0, 1 / sp.sqrt(x)), (t1, u * w)]          # t0 waits for a square root and a division
    assert (3 * u * t0 * w).as_ordered_factors() == [3, t0, u, w]     # printed ((3*t0)*u)*w: t0 early in the chain
    new_temps, new_reduced = late_factor_last(temps, [3 * u * t0 * w, -u * w * t0 * x, u * t1, 3 * u * w * t1])
    rest = dict(new_temps)
    s0 = new_reduced[0].args[0] if new_reduced[0].args[1] == t0 else new_reduced[0].args[1]
    assert new_reduced[0] == s0 * t0 and rest[s0] == 3 * u * w
    s1 = [a for a in new_reduced[1].args if a not in (-1, t0)]
    assert new_reduced[1] == -s1[0] * t0 and rest[s1[0]] == u * w * x
    assert new_reduced[2] == u * t1                       # two factors: nothing to reorder
    assert new_reduced[3] == 3 * u * w * t1               # t1 = u*w is not late
    assert [t for t, _ in new_temps][:2] == [t0, t1]
    point = {u: 0.3, w: -1.7, x: 2.9}
    value = [e.subs(list(reversed(new_temps))).subs(point) for e in new_reduced]
    want = [e.subs(list(reversed(temps))).subs(point) for e in [3 * u * t0 * w, -u * w * t0 * x, u * t1, 3 * u * w * t1]]
    assert all(abs(a - b) < 1e-12 for a, b in zip(value, want))
