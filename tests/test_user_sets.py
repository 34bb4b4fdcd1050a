"""User sets (`lavendersim derive --user FILE`): identified by their file, checked like generated/, written
atomically, CC honoured or refused, and every declaration fault one line with exit 2 (issues 28 and 31).

The CLI is run in subprocesses (its contract is the exit code and stderr), its declaration faults through
cli.main in this process (conftest.run_main; one real process per kind of fault checks that both say the same);
the manifest checks run in this process, and in a subprocess where a wrong answer would be a crash (a truncated
library).
"""
from __future__ import annotations

import ctypes
import math
import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import extending
from lavendersim.validate import LavenderInputError

from conftest import have, run_main

pytestmark = pytest.mark.needs("cc")

HEAD = ("import sympy as sp\n"
        "from lavendersim.derive.effect import STATE, effect, param\n"
        "k = param('k', unit='N·m', doc='torque about world z')\n")


def torque_decl(name: str, scale: float) -> str:
    """A declaration of one effect: torque (0, 0, scale·k), world frame."""
    return HEAD + (f"EFFECTS = [effect({name!r}, 'a torque about world z', params=[k], "
                   f"torque_w=sp.Matrix([0, 0, {scale!r} * k.symbol]))]\n")


def cli(args, env, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lavendersim", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def one_line_exit_2(r: subprocess.CompletedProcess) -> str:
    """The CLI's contract for a user error: exit 2, one line on stderr, never a traceback."""
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    return lines[0]


def snapshot(folder: Path) -> dict:
    """Every file under a folder (build/ included): relative path -> bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and "__pycache__" not in p.parts}


@pytest.fixture
def user(tmp_path, monkeypatch):
    """A fresh user directory for this process and its subprocesses."""
    u = tmp_path / "userdir"
    monkeypatch.setenv(extending.ENV, str(u))
    monkeypatch.delenv("CC", raising=False)
    return {"dir": u, "sets": u / "sets", "env": {**os.environ, extending.ENV: str(u)}, "tmp": tmp_path}


def torque_after(effect: str, k: float, backend: str = "numpy") -> float:
    """omega_z of a unit-inertia sphere after 10 steps of 0.1 s under the effect (= 10·0.1·scale·k / I)."""
    s = lv.Scene()
    s.add_body(lv.Body("b", 1.0, (1.0, 1.0, 1.0)))
    s.add_effect(effect, body="b", k=k)
    sim = lv.Sim(s, dt=0.1, integrator="rk4", backend=backend)
    sim.run(10)
    return float(sim.x[0, 12])


# ---------------------------------------------------------------- identity

def test_the_same_name_from_another_folder_is_refused_naming_both(user):
    a, b = user["tmp"] / "a", user["tmp"] / "b"
    a.mkdir()
    b.mkdir()
    (a / "twin.py").write_text(torque_decl("us_twin_a", 1.0))
    (b / "twin.py").write_text(torque_decl("us_twin_b", 10.0))
    r = cli(["derive", "--user", a / "twin.py"], {**user["env"], "CC": "gcc"}, user["tmp"])
    assert r.returncode == 0, r.stderr
    folder = user["sets"] / "twin"
    assert extending.read_manifest(folder)["library"]["compiler"] == ["gcc"]   # CC=gcc is the compiler used
    before = snapshot(folder)
    line = one_line_exit_2(cli(["derive", "--user", b / "twin.py"], user["env"], user["tmp"]))
    assert str(a / "twin.py") in line and str(b / "twin.py") in line
    assert snapshot(folder) == before                                # the first file's set untouched
    with pytest.raises(extending.UserSetError) as e:                 # loading the second never gives the first
        extending.load(b / "twin.py")
    assert str(a / "twin.py") in str(e.value) and str(b / "twin.py") in str(e.value)
    s = extending.load(a / "twin.py")
    assert s.effect_names == ["us_twin_a"] and s.declaration == (a / "twin.py").resolve()
    assert torque_after("us_twin_a", 0.5) == pytest.approx(0.5, rel=1e-12)
    assert torque_after("us_twin_a", 0.5, backend="c") == pytest.approx(0.5, rel=1e-12)
    (a / "twin.py").unlink()                                         # the first file is gone: the name is free
    r = cli(["derive", "--user", b / "twin.py"], user["env"], user["tmp"])
    assert r.returncode == 0 and f"replaced the set derived from {a / 'twin.py'}" in r.stdout, r.stderr
    s = extending.load(b / "twin.py")           # this process had the first file's set cached: not returned
    assert s.declaration == (b / "twin.py").resolve() and s.effect_names == ["us_twin_b"]
    assert torque_after("us_twin_b", 0.5) == pytest.approx(5.0, rel=1e-12)


def test_an_effect_name_two_sets_declare_is_refused_naming_both(user):
    one, two = user["tmp"] / "one.py", user["tmp"] / "two.py"
    one.write_text(torque_decl("us_shared", 1.0))
    two.write_text(torque_decl("us_shared", 10.0))
    extending.derive(one, compile=False)
    line = one_line_exit_2(cli(["derive", "--user", two], user["env"], user["tmp"]))
    assert str(one) in line and str(two) in line and "us_shared" in line
    assert not (user["sets"] / "two").exists()
    other = user["tmp"] / "elsewhere"                                # another folder: derived, but never both loaded
    with pytest.raises(extending.UserSetError) as e:
        extending.derive(two, out=other, compile=False)              # derive loads it: the clash is found there
    assert str(one) in str(e.value) and str(two) in str(e.value)
    assert lv.effects.REGISTRY["us_shared"].user_set.declaration == one.resolve()   # nothing half-registered
    assert torque_after("us_shared", 0.5) == pytest.approx(0.5, rel=1e-12)
    assert extending.read_manifest(user["sets"] / "one")["library"] is None       # derived without compiling:
    assert torque_after("us_shared", 0.5, backend="c") == pytest.approx(0.5, rel=1e-12)   # compiled on first use,
    m = extending.read_manifest(user["sets"] / "one")                            # recorded in the manifest
    assert extending.build(user["sets"] / "one") == user["sets"].resolve() / "one" / m["library"]["file"]
    shutil.move(str(other / "two"), str(user["sets"] / "two"))       # two sets in the user directory, one name
    with pytest.raises(extending.UserSetError) as e:
        extending.discover("us_shared")
    assert str(one) in str(e.value) and str(two) in str(e.value)


# ---------------------------------------------------------------- manifest

@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    """One compiled set; each test works on a copy of its folder."""
    root = tmp_path_factory.mktemp("checked")
    decl = root / "us_checked.py"
    decl.write_text(torque_decl("us_checked_push", 1.0))
    s = extending.derive(decl, out=root / "sets")
    return {"folder": s.directory, "decl": decl, "lib": s.library_path}


def copy_of(checked, tmp_path) -> Path:
    d = tmp_path / "us_checked"
    shutil.copytree(checked["folder"], d)
    return d


@pytest.mark.parametrize("name,edit", [
    ("kernels.c", lambda t: t.replace("#include <math.h>", "#include <math.h>\n#define k (10.0*k)")),  # 10x torques
    ("kernels_numpy.py", lambda t: t + "\nimport os\nos.environ['US_EDITED_RAN'] = '1'\n"),
    ("effects_meta.py", lambda t: t + "\n"),
    ("EQUATIONS.md", lambda t: t[: len(t) // 2]),                        # cut mid-file
])
def test_an_edited_or_cut_printed_file_is_refused_before_it_is_run(checked, tmp_path, name, edit):
    d = copy_of(checked, tmp_path)
    (d / name).write_text(edit((d / name).read_text()))
    with pytest.raises(extending.UserSetError) as e:
        extending.UserSet(d)
    assert e.value.field == "user set" and f"{d / name}" in str(e.value) and "derive --user" in str(e.value)
    assert "US_EDITED_RAN" not in os.environ                         # the edited module never ran


def test_a_set_without_its_manifest_is_refused(checked, tmp_path):
    d = copy_of(checked, tmp_path)
    (d / "manifest.json").unlink()
    with pytest.raises(extending.UserSetError, match="no manifest.json"):
        extending.UserSet(d)


SCRIPT = """
import sys
import lavendersim as lv
from lavendersim import extending
s = extending.load(sys.argv[1])
sc = lv.Scene()
sc.add_body(lv.Body("b", 1.0, (1.0, 1.0, 1.0)))
sc.add_effect("us_checked_push", body="b", k=1.0)
try:
    lv.Sim(sc, dt=0.1, backend="c").run(1)
except lv.LavenderInputError as e:
    print("refused:", type(e).__name__, e)
else:
    print("stepped")
"""


@pytest.mark.parametrize("damage", ["truncated", "swapped", "intact"])
def test_a_swapped_or_truncated_library_is_refused_before_it_is_loaded(checked, tmp_path, damage):
    """In a subprocess: a truncated library mapped by the loader was a SIGBUS; it is refused by its sha256."""
    d = copy_of(checked, tmp_path)
    lib = d / checked["lib"].relative_to(checked["folder"])
    data = lib.read_bytes()
    if damage == "truncated":
        lib.write_bytes(data[: len(data) // 3])
    elif damage == "swapped":       # a loadable library, not this set's (the package's own C extension)
        shutil.copyfile(next(Path(lv.__file__).parent.glob("_lavender_c*.so")), lib)
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(d)], capture_output=True, text=True, timeout=300,
                       env={**os.environ, extending.ENV: str(tmp_path / "none")})
    assert r.returncode == 0, (r.returncode, r.stderr)             # never a signal
    if damage == "intact":
        assert r.stdout.strip() == "stepped"
    else:
        assert r.stdout.startswith("refused: UserSetError") and str(lib) in r.stdout and "does not match" in r.stdout


# ---------------------------------------------------------------- atomic: a failed derive keeps the last good set

def test_a_failed_derive_exits_2_and_keeps_the_last_good_set(user):
    decl = user["tmp"] / "us_keep.py"
    good = torque_decl("us_keep_push", 1.0)
    decl.write_text(good)
    r = run_main("derive", "--user", decl, cwd=user["tmp"])           # the last good set (in this process)
    assert r.returncode == 0, r.stderr
    folder = user["sets"] / "us_keep"
    before = snapshot(folder)
    failcc = user["tmp"] / "failcc"
    failcc.write_text("#!/bin/sh\necho 'kernels.c:9:5: error: boom' >&2\necho 'more output' >&2\nexit 1\n")
    failcc.chmod(0o755)
    decl.write_text(torque_decl("us_keep_push", 2.0))                # new C, which fails to compile
    (user["sets"] / ".us_keep.compile-999999999-x1").mkdir()         # left by a compile killed earlier: removed
    line = one_line_exit_2(cli(["derive", "--user", decl], {**user["env"], "CC": str(failcc)}, user["tmp"]))
    assert "error: boom" in line and "exit 1" in line and "us_keep.compile.log" in line
    assert "more output" in (user["sets"] / "us_keep.compile.log").read_text()
    assert snapshot(folder) == before
    decl.write_text(HEAD + "raise RuntimeError('a declaration that fails in Python')\n")
    line = one_line_exit_2(cli(["derive", "--user", decl], user["env"], user["tmp"]))
    assert "line 4" in line and "a declaration that fails in Python" in line
    assert snapshot(folder) == before and not [p for p in user["sets"].iterdir() if p.name.startswith(".")]
    decl.write_text(good)                                            # the declaration of the last good set
    s = extending.load(decl)
    s.library()
    assert torque_after("us_keep_push", 0.5, backend="c") == pytest.approx(0.5, rel=1e-12)


# ---------------------------------------------------------------- CC

def test_cc_is_honoured_or_refused(user):
    decl = user["tmp"] / "us_cc.py"
    decl.write_text(torque_decl("us_cc_push", 1.0))
    line = one_line_exit_2(cli(["derive", "--user", decl], {**user["env"], "CC": "/nonexistent/cc"}, user["tmp"]))
    assert "CC='/nonexistent/cc'" in line and "not an executable" in line
    assert not (user["sets"] / "us_cc").exists()
    calls = user["tmp"] / "calls.txt"
    wrapper = user["tmp"] / "my cc"                                  # a path with a space, quoted as a shell would
    wrapper.write_text(f"#!/bin/sh\necho \"$@\" >> '{calls}'\nexec gcc \"$@\"\n")
    wrapper.chmod(0o755)
    r = cli(["derive", "--user", decl], {**user["env"], "CC": f"'{wrapper}'"}, user["tmp"])
    assert r.returncode == 0, r.stderr
    assert "-std=c99" in calls.read_text() and f"compiled with {wrapper}" in r.stdout
    assert extending.read_manifest(user["sets"] / "us_cc")["library"]["compiler"] == [str(wrapper)]


# ---------------------------------------------------------------- declaration faults: one line, exit 2

FAULTS = {
    "effects_not_a_list": ("EFFECTS = 5\n", ["EFFECTS must be a list", "got int 5"]),
    "kernels_not_kernels": ("KERNELS = ['not a kernel']\n", ["KERNELS[0] must be", "str"]),
    "unprintable": ("EFFECTS = [effect('us_bessel', 's', params=[k], force_w=sp.Matrix([sp.besselj(0, STATE.m), 0, 0]))]\n",
                    ["effect 'us_bessel'", "besselj()", "C printer"]),
    "undefined_function": ("g = sp.Function('g')\n"
                           "EFFECTS = [effect('us_undef', 's', params=[k], torque_w=sp.Matrix([g(STATE.m), 0, 0]))]\n",
                           ["effect 'us_undef'", "g()"]),
    "recursion_deep": ("e = 0\nfor i in range(5000):\n    e = e * STATE.m + k.symbol\n"
                       "EFFECTS = [effect('us_deep', 's', params=[k], force_w=sp.Matrix([e, 0, 0]))]\n",
                       ["line 7", "nested too deeply", "sp.Add(*terms)"]),
    "state_typo": ("EFFECTS = [effect('us_typo', 's', params=[k], force_w=-k.symbol * STATE.v_x)]\n",
                   ["line 4", "STATE has no field 'v_x'", "v_w"]),
    "bad_shape": ("EFFECTS = [effect('us_shape', 's', params=[k], force_w=sp.Matrix([k.symbol, 0]))]\n",
                  ["effect us_shape", "force_w must be a 3-vector", "(2, 1)"]),
    "syntax": ("EFFECTS = [\n", ["not valid Python"]),
}


@pytest.mark.parametrize("case", sorted(FAULTS))
def test_every_declaration_fault_is_one_line_and_exit_2(user, case):
    """Through cli.main in this process (run_main: the command's parser, guard and messages); the process itself
    says the same (test_the_command_line_process_says_what_main_says)."""
    text, want = FAULTS[case]
    decl = user["tmp"] / "us_fault.py"
    decl.write_text(HEAD + text)
    line = one_line_exit_2(run_main("derive", "--user", decl, cwd=user["tmp"]))
    assert str(decl) in line
    for w in want:
        assert w in line, (w, line)
    assert not (user["sets"] / "us_fault").exists()


@pytest.mark.parametrize("case", ["unprintable", "state_typo"])
def test_the_command_line_process_says_what_main_says(user, case):
    """`python -m lavendersim derive --user` (a real process: its exit code and stderr are the contract) gives what
    run_main gives for a declaration fault: an error while printing, and one while running the user's file."""
    decl = user["tmp"] / "us_fault.py"
    decl.write_text(HEAD + FAULTS[case][0])
    r = cli(["derive", "--user", decl], user["env"], user["tmp"])
    m = run_main("derive", "--user", decl, cwd=user["tmp"])
    assert (r.returncode, r.stdout, r.stderr) == (m.returncode, m.stdout, m.stderr)
    one_line_exit_2(r)


# ---------------------------------------------------------------- functions C99 and CasADi both have (issue 31)

FUNCS = HEAD + """from lavendersim.derive.kernel import Arg, Kernel, scalar
x = scalar("x")
out = sp.Matrix([sp.tanh(x), sp.sign(x), sp.floor(x), sp.ceiling(x), sp.erf(x), sp.sinh(x), sp.asinh(x)])
KERNELS = [Kernel("funcs", "tanh, sign, floor, ceil, erf, sinh, asinh of x", "", [Arg("x", x, "a number")],
                  [Arg("y", out, "the functions of x")])]
EFFECTS = [effect("us_tanh_drag", "a saturated drag", params=[k], force_w=-k.symbol * STATE.v_w.applyfunc(sp.tanh))]
"""


def test_tanh_sign_floor_ceil_erf_print_for_c_numpy_and_casadi(user):
    decl = user["tmp"] / "us_funcs.py"
    decl.write_text(FUNCS)
    s = extending.derive(decl)
    xs = [-2.5, -1.0, -0.3, 0.0, 0.4, 1.0, 2.7]
    for x in xs:
        want = [math.tanh(x), float(np.sign(x)), math.floor(x), math.ceil(x), math.erf(x), math.sinh(x), math.asinh(x)]
        c = np.zeros(7)
        s.library().lvu_us_funcs_funcs(ctypes.c_double(x), c.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
        assert np.array_equal(c, want), (x, c, want)                 # the C library's functions, bit for bit
        np.testing.assert_array_max_ulp(s.numpy.funcs(x), np.array(want), maxulp=1)   # NumPy's own tanh: 1 ulp off
        if have("control"):
            assert np.allclose(np.asarray(s.casadi.funcs(x)).ravel(), want, rtol=1e-15, atol=0)
    assert np.array_equal(s.numpy.funcs(np.array(xs))[:, 4], [math.erf(x) for x in xs])   # vectorized
    v = []
    for backend in ("c", "numpy"):                                   # the effect steps alike on both backends
        sc = lv.Scene()
        sc.add_body(lv.Body("b", 2.0, (1.0, 1.0, 1.0), v_w=(1.0, -2.0, 3.0)))
        sc.add_effect("us_tanh_drag", body="b", k=0.5)
        sim = lv.Sim(sc, dt=0.01, integrator="rk4", backend=backend)
        sim.run(20)
        v.append(sim.x[0, 7:10].copy())
    # not bitwise: NumPy's tanh is not the C library's (1 ulp apart at some arguments, e.g. 2.7)
    assert np.allclose(v[0], v[1], rtol=1e-14, atol=0) and np.all(np.abs(v[0]) < [1.0, 2.0, 3.0])


def test_the_new_errors_pickle_with_their_fields():
    e = pickle.loads(pickle.dumps(extending.UserBuildError("one line", "full\noutput", "/x.log")))
    assert (e.summary, e.output, e.log) == ("one line", "full\noutput", "/x.log")
    u = pickle.loads(pickle.dumps(extending.UserSetError("user set", "a rule", "; detail")))
    assert isinstance(u, LavenderInputError) and (u.field, u.rule, u.detail) == ("user set", "a rule", "; detail")
