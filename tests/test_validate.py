"""Tests for lavendersim.validate: every rule has an accept and a reject test."""

from __future__ import annotations

import fractions
import importlib.util
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

VALIDATE_PATH = Path(__file__).resolve().parents[1] / "lavendersim" / "validate.py"

try:
    from lavendersim import validate as V
except ImportError:  # package not importable (not installed / not on sys.path)
    _spec = importlib.util.spec_from_file_location("_lavendersim_validate", VALIDATE_PATH)
    V = importlib.util.module_from_spec(_spec)
    sys.modules[_spec.name] = V  # so pickling can find LavenderInputError
    _spec.loader.exec_module(V)

E = V.LavenderInputError


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


# ---------------------------------------------------------------- the error


def test_error_is_value_error_with_field_rule_and_message():
    err = E("omega_b", "expected shape (3,)", ", got (2,)")
    assert isinstance(err, ValueError)
    assert err.field == "omega_b"
    assert err.rule == "expected shape (3,)"
    assert str(err) == "omega_b: expected shape (3,), got (2,)"


def test_error_pickles():
    err = pickle.loads(pickle.dumps(E("mass", "must be finite and > 0", ", got -1.0")))
    assert (err.field, err.rule, str(err)) == ("mass", "must be finite and > 0", "mass: must be finite and > 0, got -1.0")


# ---------------------------------------------------------------- vector / array


@pytest.mark.parametrize(
    "value",
    [[1, 2, 3], (1.0, 2.0, 3.0), np.array([1, 2, 3], dtype=np.int32), np.array([1, 2, 3], dtype=np.float32),
     [np.float64(1), np.int64(2), 3], [fractions.Fraction(1), 2, 3]],
)
def test_vector_accepts_real_numbers(value):
    out = V.vector("omega_b", value)
    assert out.dtype == np.float64
    assert out.shape == (3,)
    assert out.flags.c_contiguous
    np.testing.assert_array_equal(out, [1.0, 2.0, 3.0])


def test_vector_n():
    out = V.vector("x", [1.5, -2.5], n=2)
    np.testing.assert_array_equal(out, [1.5, -2.5])
    assert out.dtype == np.float64


def test_vector_returns_fresh_copy_and_does_not_mutate():
    src = np.array([1.0, 2.0, 3.0])
    before = src.copy()
    out = V.vector("v", src)
    assert out is not src and not np.shares_memory(out, src)
    out[0] = 99.0
    np.testing.assert_array_equal(src, before)
    lst = [1.0, 2.0, 3.0]
    V.vector("v", lst)
    assert lst == [1.0, 2.0, 3.0]


def test_vector_accepts_read_only_input():
    src = np.array([1.0, 2.0, 3.0])
    src.setflags(write=False)
    out = V.vector("v", src)
    assert out.flags.writeable


@pytest.mark.parametrize(
    "value, got",
    [([1.0, 2.0], r"\(2,\)"), ([1.0, 2.0, 3.0, 4.0], r"\(4,\)"), ([[1.0, 2.0, 3.0]], r"\(1, 3\)"),
     (1.0, r"\(\)"), ([], r"\(0,\)")],
)
def test_vector_rejects_wrong_shape(value, got):
    with pytest.raises(E, match=r"^omega_b: expected shape \(3,\), got " + got + "$") as ei:
        V.vector("omega_b", value)
    assert ei.value.field == "omega_b"
    assert ei.value.rule == "expected shape (3,)"


@pytest.mark.parametrize(
    "value, bad, index",
    [([1.0, np.nan, 3.0], "nan", "1"), ([np.inf, 0.0, 0.0], "inf", "0"), ([0.0, 1.0, -np.inf], "-inf", "2"),
     ([0.0, np.nan, np.inf], "nan", "1")],
)
def test_vector_rejects_non_finite_naming_first_index(value, bad, index):
    with pytest.raises(E, match=rf"^tau: must be finite, got {bad} at index {index}$") as ei:
        V.vector("tau", value)
    assert ei.value.field == "tau"
    assert ei.value.rule == "must be finite"


def test_vector_rejects_huge_python_int_as_non_finite():
    with pytest.raises(E, match="must be finite, got inf at index 0") as ei:
        V.vector("v", [10**400, 0, 0])
    assert ei.value.field == "v"


@pytest.mark.parametrize(
    "value, phrase",
    [("abc", "expected real numbers, got str 'abc'"),
     (b"abc", "expected real numbers, got bytes"),
     (None, "expected real numbers, got NoneType None"),
     (["1", "2", "3"], "expected real numbers, got list"),
     ([1.0, None, 3.0], "expected real numbers, got NoneType None at index 1"),
     ([1.0, object(), 3.0], "expected real numbers, got object"),
     ({"a": 1}, "expected real numbers"),
     ([[1.0, 2.0], [3.0]], "expected a rectangular array")],
)
def test_vector_rejects_non_numeric(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.vector("r", value)
    assert ei.value.field == "r"


@pytest.mark.parametrize(
    "value, phrase",
    [([1j, 0, 0], "not complex"), (np.array([1, 2, 3], dtype=complex), "not complex"),
     ([1 + 0j, 2, 3], "not complex")],
)
def test_vector_rejects_complex(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.vector("F", value)
    assert ei.value.field == "F"


@pytest.mark.parametrize(
    "value, phrase",
    [([True, False, True], r"not bools \(got a bool at index 0\)"),
     ([1.0, True, 3.0], r"not bools \(got a bool at index 1\)"),
     ([1.0, 2.0, np.bool_(True)], r"not bools \(got a bool at index 2\)"),
     (np.array([True, False, True]), "not bools, got dtype bool")],
)
def test_vector_rejects_bools(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.vector("F", value)
    assert ei.value.field == "F"


def test_array_with_free_dimension():
    pts = [[0, 0, 0], [1, 2, 3]]
    out = V.array("points", pts, (None, 3))
    assert out.dtype == np.float64 and out.shape == (2, 3)
    np.testing.assert_array_equal(out, [[0, 0, 0], [1, 2, 3]])
    assert V.array("points", np.zeros((0, 3)), (None, 3)).shape == (0, 3)


@pytest.mark.parametrize("value, got", [(np.zeros((2, 2)), r"\(2, 2\)"), (np.zeros(3), r"\(3,\)"),
                                        (np.zeros((1, 3, 1)), r"\(1, 3, 1\)")])
def test_array_rejects_wrong_shape(value, got):
    with pytest.raises(E, match=r"^points: expected shape \(N, 3\), got " + got + "$") as ei:
        V.array("points", value, (None, 3))
    assert ei.value.field == "points"


def test_array_non_finite_index_is_multi_dimensional():
    a = np.zeros((3, 3))
    a[2, 1] = np.nan
    with pytest.raises(E, match=r"must be finite, got nan at index \(2, 1\)"):
        V.array("R", a, (3, 3))


# ---------------------------------------------------------------- scalars


@pytest.mark.parametrize("value", [2, 2.0, np.float32(2.0), np.int64(2), np.array(2.0), fractions.Fraction(2)])
def test_scalar_accepts_real(value):
    out = V.scalar("k", value)
    assert type(out) is float and out == 2.0


def test_scalar_accepts_zero_and_negative_unless_constrained():
    assert V.scalar("k", -3.5) == -3.5
    assert V.scalar("k", 0.0, nonnegative=True) == 0.0
    assert V.scalar("k", 1e-300, positive=True) == 1e-300


@pytest.mark.parametrize("value, got", [(np.nan, "nan"), (np.inf, "inf"), (-np.inf, "-inf"), (10**400, "inf")])
def test_scalar_rejects_non_finite(value, got):
    with pytest.raises(E, match=rf"^k: must be finite, got {got}$") as ei:
        V.scalar("k", value)
    assert ei.value.field == "k" and ei.value.rule == "must be finite"


@pytest.mark.parametrize("value", [True, False, np.bool_(True), np.array(True)])
def test_scalar_rejects_bool(value):
    with pytest.raises(E, match="k: expected a real number") as ei:
        V.scalar("k", value)
    assert ei.value.field == "k"


@pytest.mark.parametrize(
    "value, phrase",
    [("1.0", "got str '1.0'"), (None, "got NoneType None"), (1 + 0j, "got complex"), ([1.0], "got list"),
     (np.array([1.0]), r"got an array of shape \(1,\)"), (np.array(1 + 0j), "got an array of dtype complex")],
)
def test_scalar_rejects_non_real(value, phrase):
    with pytest.raises(E, match="k: expected a real number, " + phrase) as ei:
        V.scalar("k", value)
    assert ei.value.field == "k"


def test_scalar_positive_and_nonnegative():
    with pytest.raises(E, match=r"^mass: must be finite and > 0, got -1\.0$") as ei:
        V.scalar("mass", -1.0, positive=True)
    assert ei.value.field == "mass" and ei.value.rule == "must be finite and > 0"
    with pytest.raises(E, match=r"must be finite and > 0, got 0\.0"):
        V.scalar("mass", 0, positive=True)
    with pytest.raises(E, match=r"must be finite and > 0, got nan"):
        V.scalar("mass", float("nan"), positive=True)
    with pytest.raises(E, match=r"^c: must be finite and >= 0, got -1e-09$") as ei:
        V.scalar("c", -1e-9, nonnegative=True)
    assert ei.value.field == "c"


def test_positive_shorthand():
    assert V.positive("mass", 1) == 1.0 and type(V.positive("mass", 1)) is float
    with pytest.raises(E, match=r"^mass: must be finite and > 0, got -1\.0$") as ei:
        V.positive("mass", -1.0)
    assert ei.value.field == "mass"
    with pytest.raises(E, match="mass: expected a real number"):
        V.positive("mass", True)


@pytest.mark.parametrize("value, got", [(0.0, "0.0"), (-0.01, "-0.01"), (np.inf, "inf"), (np.nan, "nan")])
def test_dt_rejects_non_positive_and_non_finite(value, got):
    with pytest.raises(E, match=rf"^dt: must be finite and > 0, got {got}$") as ei:
        V.dt("dt", value)
    assert ei.value.field == "dt"


def test_dt_accepts_positive():
    assert V.dt("dt", 0.01) == 0.01
    assert type(V.dt("dt", np.float32(0.5))) is float


# ---------------------------------------------------------------- integer / choice


@pytest.mark.parametrize("value", [3, np.int32(3), np.uint8(3), np.int64(3)])
def test_integer_accepts(value):
    out = V.integer("steps", value, minimum=1)
    assert type(out) is int and out == 3


@pytest.mark.parametrize("value", [3.0, True, np.bool_(False), "3", None, np.float64(3.0), np.array(3)])
def test_integer_rejects_non_integers(value):
    with pytest.raises(E, match="steps: expected an integer, got") as ei:
        V.integer("steps", value)
    assert ei.value.field == "steps"


def test_integer_minimum():
    assert V.integer("n", 0, minimum=0) == 0
    assert V.integer("n", -5) == -5
    with pytest.raises(E, match=r"^n: must be an integer >= 1, got 0$") as ei:
        V.integer("n", 0, minimum=1)
    assert ei.value.field == "n" and ei.value.rule == "must be an integer >= 1"


EFFECTS = {"gravity", "applied_torque", "angular_damping", "linear_damping"}


def test_choice_accepts():
    assert V.choice("effect", "gravity", EFFECTS) == "gravity"
    assert V.choice("effect", np.str_("gravity"), ["gravity"]) == "gravity"


def test_choice_rejects_unknown_with_sorted_list():
    with pytest.raises(E) as ei:
        V.choice("effect", "gravty", EFFECTS)
    msg = str(ei.value)
    assert msg.startswith(
        "effect: unknown name 'gravty'; known: angular_damping, applied_torque, gravity, linear_damping"
    )
    assert "did you mean 'gravity'" in msg
    assert ei.value.field == "effect"


@pytest.mark.parametrize("value", [None, 3, b"gravity", ["gravity"]])
def test_choice_rejects_non_string(value):
    with pytest.raises(E, match=r"effect: expected a name \(str\), got .*; known: angular_damping") as ei:
        V.choice("effect", value, EFFECTS)
    assert ei.value.field == "effect"


def test_choice_is_case_sensitive():
    with pytest.raises(E, match="unknown name 'Gravity'"):
        V.choice("effect", "Gravity", EFFECTS)


# ---------------------------------------------------------------- quaternion


def test_quaternion_unit_passes_through():
    q = [0.0, 0.0, np.sin(0.3), np.cos(0.3)]
    out = V.quaternion("q", q)
    assert out.dtype == np.float64 and out.shape == (4,)
    np.testing.assert_allclose(out, q, rtol=2e-16, atol=0)


def test_quaternion_non_unit_is_normalized_and_input_not_mutated():
    src = np.array([0.0, 0.0, 0.0, 2.0])
    out = V.quaternion("q", src)
    np.testing.assert_array_equal(out, [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_array_equal(src, [0.0, 0.0, 0.0, 2.0])
    out = V.quaternion("q", [1, 2, 2, 4])
    np.testing.assert_allclose(out, np.array([1, 2, 2, 4]) / 5.0, rtol=1e-15)
    assert abs(np.linalg.norm(out) - 1.0) < 1e-15


def test_quaternion_keeps_sign():
    np.testing.assert_array_equal(V.quaternion("q", [0, 0, 0, -1]), [0.0, 0.0, 0.0, -1.0])


def test_quaternion_extreme_scales_normalize_without_overflow():
    np.testing.assert_allclose(V.quaternion("q", [0, 0, 1e200, 1e200]), [0, 0, 2**-0.5, 2**-0.5], rtol=1e-15)
    np.testing.assert_allclose(V.quaternion("q", [0, 0, 0, 1e-200]), [0, 0, 0, 1.0], rtol=1e-15)


@pytest.mark.parametrize("value", [[0, 0, 0, 0], np.zeros(4), [0.0, -0.0, 0.0, 0.0]])
def test_quaternion_rejects_zero(value):
    with pytest.raises(E, match=r"^q: zero quaternion \(norm 0\) cannot be normalized$") as ei:
        V.quaternion("q", value)
    assert ei.value.field == "q"


def test_quaternion_rejects_subnormal_norm():
    with pytest.raises(E, match=r"zero quaternion \(norm 1e-310\)"):
        V.quaternion("q", [0, 0, 0, 1e-310])


@pytest.mark.parametrize(
    "value, phrase",
    [([0, 0, 1], r"expected shape \(4,\), got \(3,\)"), ([0, 0, np.nan, 1], "must be finite, got nan at index 2"),
     ([0, 0, 0, np.inf], "must be finite, got inf at index 3"), ("1,0,0,0", "expected real numbers"),
     (None, "expected real numbers"), ([True, False, False, False], "not bools")],
)
def test_quaternion_rejects_bad(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.quaternion("q0", value)
    assert ei.value.field == "q0"


# ---------------------------------------------------------------- inertia


def test_inertia_accepts_moments_and_diagonal_tensor():
    m = V.inertia("I_b", [1.0, 2.0, 2.5])
    assert m.dtype == np.float64 and m.shape == (3,)
    np.testing.assert_array_equal(m, [1.0, 2.0, 2.5])
    m = V.inertia("I_b", np.diag([3, 1, 2]))
    assert m.dtype == np.float64 and m.shape == (3,)
    np.testing.assert_array_equal(m, [3.0, 1.0, 2.0])


def test_inertia_chapter_bodies():
    cube = 1.0 * (0.2**2 + 0.2**2) / 12
    np.testing.assert_array_equal(V.inertia("I_b", [cube] * 3), [cube] * 3)
    rod = [(0.2**2 + 0.2**2) / 12, (0.8**2 + 0.2**2) / 12, (0.8**2 + 0.2**2) / 12]
    np.testing.assert_array_equal(V.inertia("I_b", rod), rod)


def test_inertia_flat_plate_equality_and_thin_rod_are_valid():
    np.testing.assert_array_equal(V.inertia("I_b", [1, 1, 2]), [1.0, 1.0, 2.0])
    np.testing.assert_array_equal(V.inertia("I_b", np.diag([2.0, 1.0, 1.0])), [2.0, 1.0, 1.0])
    # rectangular plate a x b: Ix = b^2/12, Iy = a^2/12, Iz = (a^2+b^2)/12 (rounding must not reject it)
    a, b = 0.3, 0.7
    plate = [b * b / 12, a * a / 12, (a * a + b * b) / 12]
    V.inertia("I_b", plate)
    np.testing.assert_array_equal(V.inertia("I_b", [1e-6, 1, 1]), [1e-6, 1.0, 1.0])


def test_inertia_does_not_mutate_input():
    t = np.diag([1.0, 2.0, 2.5])
    before = t.copy()
    out = V.inertia("I_b", t)
    out[0] = 42
    np.testing.assert_array_equal(t, before)
    v = np.array([1.0, 2.0, 2.5])
    out = V.inertia("I_b", v)
    assert not np.shares_memory(out, v)


@pytest.mark.parametrize(
    "value, phrase",
    [([1, 1, 3], r"^I_b: principal moments violate the triangle inequality I1 \+ I2 >= I3 \(got \[1, 1, 3\]\)$"),
     ([3, 1, 1], r"violate the triangle inequality I2 \+ I3 >= I1 \(got \[3, 1, 1\]\)"),
     ([1, 2.5, 1], r"violate the triangle inequality I1 \+ I3 >= I2"),
     (np.diag([1.0, 1.0, 3.0]), r"violate the triangle inequality I1 \+ I2 >= I3 \(got \[1, 1, 3\]\)"),
     ([1, 1, 2 * (1 + 1e-9)], r"triangle inequality")],
)
def test_inertia_rejects_triangle_violation(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.inertia("I_b", value)
    assert ei.value.field == "I_b"
    assert ei.value.rule.startswith("principal moments violate the triangle inequality")


def test_inertia_rejects_non_diagonal_tensor_as_physically_impossible_first():
    t = _rot([1, 1, 0], 0.4) @ np.diag([1.0, 1.0, 3.0]) @ _rot([1, 1, 0], 0.4).T
    with pytest.raises(E, match="triangle inequality"):
        V.inertia("I_b", t)


@pytest.mark.parametrize("value, got", [([1, 0, 1], r"\[1, 0, 1\]"), ([-1, 2, 2], r"\[-1, 2, 2\]")])
def test_inertia_rejects_non_positive_moments(value, got):
    with pytest.raises(E, match=r"^I_b: principal moments must be > 0 \(got " + got + r"\)$") as ei:
        V.inertia("I_b", value)
    assert ei.value.field == "I_b"


def test_inertia_rejects_asymmetric():
    t = np.diag([1.0, 2.0, 2.5])
    t[0, 1] = 0.1
    with pytest.raises(E, match="I_b: inertia tensor must be symmetric") as ei:
        V.inertia("I_b", t)
    assert ei.value.field == "I_b"
    assert ei.value.rule == "inertia tensor must be symmetric"


def test_inertia_symmetry_tolerance_is_relative():
    t = np.diag([1.0, 2.0, 2.5])
    t[0, 1] = 1e-14  # asymmetry and off-diagonal below 1e-12 * max|I| -> accepted as diagonal
    np.testing.assert_array_equal(V.inertia("I_b", t), [1.0, 2.0, 2.5])


@pytest.mark.parametrize("diag", [[1.0, -1.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
def test_inertia_rejects_non_positive_definite_tensor(diag):
    with pytest.raises(E, match="I_b: inertia tensor must be positive definite") as ei:
        V.inertia("I_b", np.diag(diag))
    assert ei.value.field == "I_b"


def test_inertia_rejects_symmetric_indefinite_with_positive_diagonal():
    t = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])  # eigenvalues -1, 1, 3
    with pytest.raises(E, match=r"must be positive definite \(eigenvalues \[-1, 1, 3\]\)"):
        V.inertia("I_b", t)


def test_inertia_rejects_non_diagonal_valid_tensor():
    R = _rot([1, 2, 3], 0.7)
    t = R @ np.diag([1.0, 2.0, 2.5]) @ R.T
    with pytest.raises(E, match=r"must be principal moments \(a diagonal tensor\) here: lavendersim\.Body takes a "
                                r"full tensor \(lavendersim\.validate\.principal_axes gives the moments and axes\)") as ei:
        V.inertia("I_b", t)
    assert ei.value.field == "I_b"
    assert ei.value.rule.startswith("must be principal moments")


@pytest.mark.parametrize(
    "value, phrase",
    [(np.eye(2), r"expected shape \(3,\) principal moments or \(3, 3\) tensor, got \(2, 2\)"),
     ([1, 2], r"got \(2,\)"), ([1, np.nan, 1], "must be finite, got nan at index 1"),
     (np.diag([1.0, np.inf, 1.0]), r"must be finite, got inf at index \(1, 1\)"),
     ("diag", "expected real numbers"), (None, "expected real numbers"), ([True, True, True], "not bools")],
)
def test_inertia_rejects_bad_shape_and_values(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.inertia("I_b", value)
    assert ei.value.field == "I_b"


# ---------------------------------------------------------------- principal_axes


@pytest.mark.parametrize(
    "moments, axis, angle",
    [([2.0, 1.0, 2.5], [1, 2, 3], 0.7), ([1.0, 1.0, 2.0], [0, 1, 1], 2.0), ([3.0, 3.0, 3.0], [1, 0, 0], 0.3),
     ([0.1, 5.0, 5.05], [-1, 0.5, 0.2], -1.1)],
)
def test_principal_axes_recovers_rotated_diagonal(moments, axis, angle):
    R0 = _rot(axis, angle)
    I = R0 @ np.diag(moments) @ R0.T
    I = 0.5 * (I + I.T)
    I_before = I.copy()
    m, R = V.principal_axes(I)
    assert m.dtype == np.float64 and R.dtype == np.float64
    assert m.shape == (3,) and R.shape == (3, 3)
    np.testing.assert_allclose(m, np.sort(moments), rtol=0, atol=1e-12 * max(moments))
    assert np.all(np.diff(m) >= 0)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12
    np.testing.assert_allclose(R.T @ R, np.eye(3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(R @ np.diag(m) @ R.T, I, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(I, I_before)
    # the returned moments pass inertia() once the body is in its principal frame
    np.testing.assert_allclose(V.inertia("I_b", R.T @ I @ R * (np.abs(R.T @ I @ R) > 1e-13)), m, atol=1e-12)


def test_principal_axes_column_is_axis():
    I = np.diag([3.0, 1.0, 2.0])
    m, R = V.principal_axes(I)
    np.testing.assert_array_equal(m, [1.0, 2.0, 3.0])
    for k in range(3):
        np.testing.assert_allclose(I @ R[:, k], m[k] * R[:, k], atol=1e-15)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12


@pytest.mark.parametrize(
    "value, phrase",
    [(np.array([[1.0, 0.1, 0], [0, 1.0, 0], [0, 0, 1.0]]), "must be symmetric"),
     (np.diag([1.0, -1.0, 1.0]), "must be positive definite"),
     (np.diag([1.0, 1.0, 3.0]), r"triangle inequality I1 \+ I2 >= I3"),
     ([1.0, 2.0, 2.5], r"expected shape \(3, 3\), got \(3,\)"),
     (np.diag([1.0, np.nan, 1.0]), "must be finite")],
)
def test_principal_axes_rejects(value, phrase):
    with pytest.raises(E, match=phrase) as ei:
        V.principal_axes(value)
    assert ei.value.field == "inertia"
    with pytest.raises(E) as ei:
        V.principal_axes(value, field="I_w")
    assert ei.value.field == "I_w"


# ---------------------------------------------------------------- python -O


def test_validation_survives_python_O():
    code = textwrap.dedent(
        f"""
        import importlib.util, sys
        assert False, "asserts must be stripped under -O"  # proves -O is active
        import lavendersim.validate as v   # the package module (it imports lavendersim.errors)
        checks = [
            lambda: v.positive("mass", -1.0),
            lambda: v.dt("dt", 0.0),
            lambda: v.vector("omega_b", [1.0, float("nan"), 0.0]),
            lambda: v.quaternion("q", [0, 0, 0, 0]),
            lambda: v.inertia("I_b", [1, 1, 3]),
            lambda: v.choice("effect", "gravty", ["gravity"]),
            lambda: v.integer("n", 1.0),
        ]
        for check in checks:
            try:
                check()
            except v.LavenderInputError:
                continue
            sys.exit("not rejected under -O")
        print("ok")
        """
    )
    proc = subprocess.run([sys.executable, "-O", "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    assert proc.stdout.strip() == "ok"


def test_module_contains_no_assert():
    import ast

    tree = ast.parse(VALIDATE_PATH.read_text())
    assert not any(isinstance(node, ast.Assert) for node in ast.walk(tree))
