"""A pass after SymPy's CSE that removes the arithmetic CSE leaves over, by exact rewrites only.

SymPy distributes a numeric coefficient over a sum (-(a - b) is stored as b - a, 2*(a + b) as 2*a + 2*b), so
CSE meets the same sum with both signs and keeps a negation temporary (`t1 = c - p; t2 = -t1`), and it does not
match `2*q*t` with `-2*r*t` (their coefficients differ), so a product by a doubled temporary is printed as two
multiplies. Every rewrite here gives the printed kernel the same value, bit for bit, for nonzero results:

- a negation moves into its uses: -x*y is -(x*y), x + (-y) is x - y and (-x)**2 is x**2 exactly in IEEE
  arithmetic (only the sign of an exact zero can differ);
- k*a*f with a temporary s = k*f, k a power of two, prints as a*s: k*a*f is (k*a)*f, and (k*a)*f = a*(k*f)
  exactly (scaling by a power of two is exact away from overflow and subnormals). Only products of k and two
  other factors are rewritten: with a third factor the printer could reorder the product.

The printers see plain SymPy expressions still, so C, NumPy and CasADi print the same operations.
"""
from __future__ import annotations

import sympy as sp


def bottom_up(e, node):
    """e with node applied to each of its compound subexpressions, innermost first (a node sees its arguments
    already rewritten; an atom is returned as is)."""
    if e.is_Atom or not e.args:
        return e
    args = [bottom_up(a, node) for a in e.args]
    return node(e.func(*args) if any(a is not b for a, b in zip(args, e.args)) else e)


def fresh_temps(temps: list):
    """Names t<n> for new temporaries, numbered after the highest t<n> of temps (a pass may have dropped some)."""
    taken = [int(t.name[1:]) for t, _ in temps if t.name[:1] == "t" and t.name[1:].isdigit()]
    return sp.numbered_symbols("t", start=max(taken, default=-1) + 1)


def tidy(temps: list, reduced: list) -> tuple[list, list]:
    """CSE's (temporaries, reduced outputs) without negation temporaries and with doubled temporaries shared.

    Parameters
    ----------
    temps : list of (Symbol, Expr)
        The temporaries in printing order, each defined from inputs and earlier temporaries.
    reduced : list of Expr
        The outputs in terms of the inputs and the temporaries.

    Returns
    -------
    (list of (Symbol, Expr), list of Expr)
        The same kernel: fewer temporaries (a dropped one's name is not reused) and the outputs rewritten.
    """
    temps, reduced = _drop_negations(temps, reduced)
    return late_factor_last(*_share_scaled(temps, reduced))


def _negated_symbol(e) -> bool:
    """Whether e is -x for a symbol x."""
    return bool(e.is_Mul and len(e.args) == 2 and e.args[0] == -1 and e.args[1].is_Symbol)


def _drop_negations(temps: list, reduced: list) -> tuple[list, list]:
    """Each temporary t = -x (x a symbol) replaced by -x where it is used; SymPy folds the sign into the product,
    sum or even power it meets."""
    subs: dict = {}
    out = []
    for t, e in temps:
        e = e.xreplace(subs) if subs else e
        if _negated_symbol(e):
            subs[t] = e
        else:
            out.append((t, e))
    return out, [e.xreplace(subs) if subs else e for e in reduced]


def _power_of_two(k) -> bool:
    """Whether |k| is 2**n for an integer n ≠ 0 (a rational k = ±p/q with p or q a power of two and the other 1)."""
    if not k.is_Rational or k == 0:
        return False
    p, q = abs(int(k.p)), int(k.q)
    return (p == 1) != (q == 1) and (p & (p - 1)) == 0 and (q & (q - 1)) == 0


def _share_scaled(temps: list, reduced: list) -> tuple[list, list]:
    """k*a*f printed as a*s where a temporary s = k*f exists (k a power of two; its sign may differ)."""
    scaled: dict = {}     # (|k|, f) -> s

    def share_node(e):
        if not e.is_Mul or len(e.args) != 3 or not e.args[0].is_Number:
            return e
        k, x, y = e.args
        for a, f in ((x, y), (y, x)):
            s = scaled.get((abs(k), f))
            if s is not None:
                sign = 1 if (k > 0) == (s[1] > 0) else -1
                return sign * a * s[0]
        return e

    for t, e in temps:
        if _scaled_symbol(e):
            scaled.setdefault((abs(e.args[0]), e.args[1]), (t, e.args[0]))
    movable = {t for t, _ in scaled.values()}
    out = [(t, e) for t, e in _early(temps, movable)]
    def share(e):
        return bottom_up(e, share_node)

    return [(t, e if t in movable else share(e)) for t, e in out], [share(e) for e in reduced]


def _scaled_symbol(e) -> bool:
    """Whether e is k*f for a power of two k and a symbol f."""
    return bool(e.is_Mul and len(e.args) == 2 and _power_of_two(e.args[0]) and e.args[1].is_Symbol)


def _early(temps: list, movable: set) -> list:
    """temps with each of `movable` (defined from one symbol) placed just after that symbol's definition (first if
    it is an input), so every temporary may use it."""
    rest = [(t, e) for t, e in temps if t not in movable]
    moved = {t: e for t, e in temps if t in movable}
    after: dict = {}
    for t, e in moved.items():
        after.setdefault(e.args[1], []).append((t, e))
    defined = {t for t, _ in rest}
    out = [te for f, tes in after.items() if f not in defined for te in tes]
    for t, e in rest:
        out.append((t, e))
        out.extend(after.get(t, []))
    return out


# A rough latency model (cycles) of the printed operations, to find the factor of a product that is ready last.
_LAT_ADD, _LAT_MUL, _LAT_DIV, _LAT_SQRT = 3, 3, 13, 20
_LATE = 10            # a factor this much later than all the others is multiplied in last


def _latency(e, ready: dict) -> int:
    """When e's value is ready, in the model, given the ready times of the temporaries (inputs are ready at 0)."""
    if e.is_Symbol:
        return ready.get(e, 0)
    if e.is_Atom or not e.args:
        return 0
    start = max(_latency(a, ready) for a in e.args)
    if e.is_Pow:
        x = e.exp
        cost = (_LAT_SQRT if not x.is_Integer else _LAT_MUL) + (_LAT_DIV if x.is_negative else 0)
        return start + cost
    return start + (_LAT_ADD if e.is_Add else _LAT_MUL)


def late_factor_last(temps: list, reduced: list) -> tuple[list, list]:
    """Each product with one factor (a temporary) ready well after all its others printed as (the others) * late:
    the others get a temporary of their own, computed while the late one (a square root, a division) is still on
    its way, so one multiply, not several, follows it. As many multiplies; the product is reassociated, so its
    value can change in the last bit (C and NumPy print the same form)."""
    names = fresh_temps(temps)
    ready: dict = {}
    named: dict = {}      # a product of the others -> its temporary
    out: list = []

    def split_node(e):
        if not e.is_Mul or len(e.args) < 3:
            return e
        late = max((a for a in e.args if a.is_Symbol), key=lambda a: ready.get(a, 0), default=None)
        if late is None:
            return e
        sign = -1 if e.args[0] == -1 else 1
        others = [a for a in e.args if a is not late and not (sign < 0 and a == -1)]
        if len(others) < 2 or ready.get(late, 0) < max(_latency(a, ready) for a in others) + _LATE:
            return e
        if e.as_ordered_factors()[-1] == late:      # printed last already (a left fold)
            return e
        rest = sp.Mul(*others)
        if rest not in named:
            named[rest] = next(names)
            out.append((named[rest], rest))
            ready[named[rest]] = _latency(rest, ready)
        return sign * named[rest] * late

    def split(e):
        return bottom_up(e, split_node)

    for t, e in temps:
        e = split(e)
        out.append((t, e))
        ready[t] = _latency(e, ready)
    return out, [split(e) for e in reduced]
