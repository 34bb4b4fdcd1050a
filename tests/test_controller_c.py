"""Issue 27: the designed controller printed as C99, compiled with the strict flags, verified in the loop.

Two spacecraft: the shipped 6U CubeSat (4 pyramid wheels, null-space bias, 10 Hz, 10 ms delay and a
20 ms actuator lag: 8 numbers of controller memory) and one of this test's own (another tensor, three
skewed wheels, 5 Hz, bearing damping, no delay and no lag: no memory, the C99 one-slot case). Each is
printed, compiled with ``cc -std=c99 -Wall -Wextra -pedantic -Werror`` (the float32 step also with
-Wdouble-promotion -Wfloat-conversion), flown in closed_loop in place of the Python controller on the
same plant and sensor noise (float64: commands <= 1e-12 relative, trajectory <= 1e-9; float32: settling
within 5 %), fed random states within the design's envelope (finite, within the torque limit), and
exported twice (byte-identical). The CLI's --export-c writes the files and reports the same figures.
"""
from __future__ import annotations

import json
import subprocess
import tomllib

import numpy as np
import pytest

from conftest import IN_CI, require

pytestmark = pytest.mark.needs("control")

OWN = """
name = "3U, three skewed wheels, 5 Hz, no delay, no lag"

[body]
name = "bus"
mass = 4.0
inertia = [[0.05, 0.003, -0.001],
           [0.003, 0.045, 0.002],
           [-0.001, 0.002, 0.015]]

[body.wheels]
axes_b = [[1.0, 0.3, -0.1], [0.2, 1.0, 0.1], [0.1, -0.3, 1.0]]   # skewed, scaled to unit by the reader
J = [2e-5, 2e-5, 1.5e-5]
torque_limit = 0.0015
speed_limit = 700.0
c_w = 1e-7
motor = "line"

[controller]
period = 0.2                  # 5 Hz, no delay, no actuator lag: the controller has no memory

[controller.weights]
attitude_deg = 1.0
rate = 0.02

[sensors]
attitude_noise = 5e-5
gyro_noise = 1e-5
gyro_bias = [1e-5, 0.0, -1e-5]
wheel_speed_noise = 0.1
seed = 11

[maneuver]
angle_deg = 25.0
axis = [0.5, -1.0, 1.5]
duration = 40.0
settle_within = 20.0

[simulator]
dt = 0.02
"""


@pytest.fixture(scope="module")
def designs(tmp_path_factory):
    from lavendersim import spacecraft as S

    own = tmp_path_factory.mktemp("own") / "own.toml"
    own.write_text(OWN, encoding="utf-8")
    out = {}
    for name, src in (("cubesat6u", "cubesat6u"), ("own", str(own))):
        sc = S.load(src)
        out[name] = (sc, S.design(sc), src)
    return out


@pytest.fixture(scope="module")
def sil_reports(designs, tmp_path_factory):
    """Each spacecraft's maneuver flown by the Python controller and by the printed C (float64, float32)."""
    require("cc")
    from lavendersim import controller_c as CC
    from lavendersim import spacecraft as S

    reps = {}
    for name, (sc, ctrl, _) in designs.items():
        ref = S.fly(sc, ctrl)
        reps[name] = (CC.verify(ctrl, lambda c, sc=sc: S.fly(sc, c), reference=ref,
                                directory=tmp_path_factory.mktemp(f"sil_{name}")), ref)
    return reps


def _strict(cmd_dir, *sources, out="a.out", extra=()):
    from lavendersim.controller_c import STRICT
    from lavendersim.extending import compiler

    cmd = [*compiler(), *STRICT, *extra, *sources, "-o", out, "-lm"]
    r = subprocess.run(cmd, cwd=cmd_dir, capture_output=True, text=True)
    assert r.returncode == 0, f"$ {' '.join(cmd)}\n{r.stdout}{r.stderr}"
    return r


# ---------------------------------------------------------------------------------------------
# the printed files
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["cubesat6u", "own"])
def test_printed_pair_compiles_strict_and_main_prints_the_python_command(designs, name, tmp_path):
    require("cc")
    from lavendersim import controller_c as CC

    sc, ctrl, _ = designs[name]
    p = CC.export_c(ctrl, tmp_path, source=f"{name}.toml")
    assert sorted(x.name for x in tmp_path.iterdir()) == ["controller.c", "controller.h", "main.c"]
    h = (tmp_path / "controller.h").read_text()
    for needle in (f"#define LV_CONTROLLER_N {ctrl.n} ", f"LV_CONTROLLER_PERIOD {ctrl.Ts!r} ", f"body {ctrl.body!r}",
                   f"from {name}.toml", "(x, y, z, w)", "body frame, rad/s", "N*m", "int lv_controller_step(",
                   "int lv_controller_step_f32(const float q[4]", f"LV_CONTROLLER_TORQUE_LIMIT {ctrl.wheels.torque_limit!r}"):
        assert needle in h, needle
    c = (tmp_path / "controller.c").read_text()
    assert "malloc" not in c and "static double" not in c and c.count("#include") == 2   # controller.h, math.h
    # the example program, compiled with the flags, prints exactly what Controller.command computes
    _strict(tmp_path, "main.c", "controller.c", out="main")
    run = subprocess.run(["./main"], cwd=tmp_path, capture_output=True, text=True, check=True)
    u_c = [float(line.split("=")[1].split()[0]) for line in run.stdout.splitlines()]
    from lavendersim.kernels import K as KN

    q = np.asarray(KN.quat_mul(ctrl.q_ref, KN.axis_angle_to_quat(np.array([1.0, 0, 0]), np.radians(10))), float)
    ctrl.reset()
    np.testing.assert_array_equal(u_c, ctrl.command(q, np.zeros(3), ctrl.Omega_ref))
    assert p.n_ops > 50 and p.lines["controller.c"] > 100


def test_float32_step_has_no_double_arithmetic(designs, tmp_path):
    """A float-only FPU target: the float32 step compiles with -Wdouble-promotion -Wfloat-conversion -Werror,
    and alone (the float64 step removed from the file) uses no double-precision libm call."""
    require("cc")
    from lavendersim import controller_c as CC

    _, ctrl, _ = designs["cubesat6u"]
    p = CC.export_c(ctrl, tmp_path)
    _strict(tmp_path, "controller.c", out="c.o", extra=("-c", "-Wdouble-promotion", "-Wfloat-conversion"))
    c = p.files["controller.c"]
    f32 = c[c.index("static const float"):]
    assert "fminf(" in f32 and "fmaxf(" in f32 and " fmin(" not in f32 and "double" not in f32


def test_m32_when_the_toolchain_has_it(designs, tmp_path):
    """-m32 (a 32-bit target) needs 32-bit libc (gcc-multilib); this test skips, naming why, where it is missing.
    Measured with it: i386's default x87 arithmetic (80-bit registers, double rounding) prints commands within
    ~2e-15 relative of the 64-bit build's; with -msse2 -mfpmath=sse they are bit-identical."""
    require("cc")
    from lavendersim import controller_c as CC
    from lavendersim.extending import compiler

    probe = tmp_path / "probe.c"
    probe.write_text("#include <math.h>\nint main(void) { return (int)sqrt(0.0); }\n")
    r = subprocess.run([*compiler(), "-m32", "probe.c", "-o", "probe", "-lm"], cwd=tmp_path, capture_output=True, text=True)
    if r.returncode != 0:
        why = next((ln for ln in r.stderr.splitlines() if "error" in ln), r.stderr.strip())
        why = f"the C compiler cannot build for -m32 here (no 32-bit libc: apt-get install gcc-multilib): {why.strip()}"
        if IN_CI:   # .ci/run installs gcc-multilib: under CI=true a missing 32-bit toolchain is a failure
            pytest.fail(why, pytrace=False)
        pytest.skip(why)
    ctrl = designs["cubesat6u"][1]
    CC.export_c(ctrl, tmp_path)
    outs = {}
    for tag, extra in (("64", ()), ("x87", ("-m32",)), ("sse", ("-m32", "-msse2", "-mfpmath=sse"))):
        _strict(tmp_path, "main.c", "controller.c", out=f"main{tag}", extra=extra)
        run = subprocess.run([f"./main{tag}"], cwd=tmp_path, capture_output=True, text=True, check=True)
        outs[tag] = np.array([float(line.split("=")[1].split()[0]) for line in run.stdout.splitlines()])
    np.testing.assert_array_equal(outs["sse"], outs["64"])
    np.testing.assert_allclose(outs["x87"], outs["64"], rtol=1e-12, atol=0)


def test_two_exports_are_byte_identical(designs, tmp_path):
    from lavendersim import controller_c as CC
    from lavendersim import spacecraft as S

    sc, ctrl, _ = designs["cubesat6u"]
    CC.export_c(ctrl, tmp_path / "a", source="cubesat6u")                            # the designed controller
    CC.export_c(S.design(S.load("cubesat6u")), tmp_path / "b", source="cubesat6u")   # designed again
    for f in CC.FILES:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f


def test_bad_arguments_are_named(designs, tmp_path):
    from lavendersim import controller_c as CC
    from lavendersim.validate import LavenderInputError

    ctrl = designs["own"][1]
    with pytest.raises(LavenderInputError, match="prefix"):
        CC.render(ctrl, prefix="1bad")
    with pytest.raises(LavenderInputError, match="controller"):
        CC.render("not a controller")
    (tmp_path / "file").write_text("x")
    with pytest.raises(LavenderInputError, match="directory"):
        CC.export_c(ctrl, tmp_path / "file" / "sub")
    with pytest.raises(LavenderInputError, match="precision"):
        CC.CompiledController(ctrl, precision="float16")


def test_a_compiler_failure_shows_the_command_and_output(designs, monkeypatch):
    require("cc")
    from lavendersim import controller_c as CC

    monkeypatch.setenv("CC", "cc -DLV_BROKEN -include /nonexistent/header.h")
    with pytest.raises(CC.CompileError, match=r"(?s)\$ cc -DLV_BROKEN.*nonexistent/header\.h"):
        CC.compile_library(CC.render(designs["own"][1]))


# ---------------------------------------------------------------------------------------------
# software in the loop
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["cubesat6u", "own"])
def test_sil_float64_agrees_with_python(sil_reports, designs, name):
    rep, ref = sil_reports[name]
    assert rep.samples == ref.t.size - 1 >= 200
    assert rep.command_rel_f64 <= 1e-12 and rep.trajectory_diff_f64 <= 1e-9
    assert rep.commands_identical_f64      # measured: the same IEEE operations in CasADi's order, bit for bit
    assert rep.settling_time_f64 == rep.settling_time_python <= designs[name][0].maneuver.settle_within
    assert "-std=c99 -Wall -Wextra -pedantic -Werror" in rep.compile_command and rep.ok


@pytest.mark.parametrize("name", ["cubesat6u", "own"])
def test_sil_float32_settles_within_5_percent(sil_reports, designs, name):
    rep, ref = sil_reports[name]
    lim = designs[name][1].wheels.torque_limit
    assert rep.settle_rel_f32 <= 0.05
    # measured: 2.5e-9 N·m (CubeSat, 1.2e-6 of the limit), 6.5e-10 (own); float32 rounding is ~6e-8 relative
    assert 0 < rep.command_diff_f32 <= 1e-5 * lim and 0 < rep.command_diff_f32_replay <= 1e-5 * lim
    assert 0 < rep.trajectory_diff_f32 <= 1e-3


@pytest.mark.parametrize("name", ["cubesat6u", "own"])
def test_bounded_inputs(designs, name):
    """Random states within the design's envelope (any attitude and reference, |omega| <= 0.5 rad/s, wheel rates
    within the speed limit, memory within the torque limit): finite commands within the limit, both precisions;
    a non-finite input is refused (returns 1, u = u0, z unchanged)."""
    require("cc")
    from lavendersim import controller_c as CC

    _, ctrl, _ = designs[name]
    wh = ctrl.wheels
    rng = np.random.default_rng(27)
    printed = CC.render(ctrl)
    lib, cmd = CC.compile_library(printed)
    for prec in ("float64", "float32"):
        cc = CC.CompiledController(ctrl, precision=prec, printed=printed, library=lib, command=cmd)
        worst, hits = 0.0, 0
        for _ in range(400):
            q, qr = (v / np.linalg.norm(v) for v in rng.normal(size=(2, 4)))
            w = rng.uniform(-0.5, 0.5, 3)
            Om = rng.uniform(-wh.speed_limit, wh.speed_limit, ctrl.n)
            cc._zbuf[:ctrl.nz] = rng.uniform(-wh.torque_limit, wh.torque_limit, ctrl.nz)
            u = cc.command(q, w, Om, qr)
            assert np.all(np.isfinite(u)) and np.all(np.isfinite(cc.z))
            worst = max(worst, float(np.abs(u).max()))
            hits += int(np.any(np.abs(u) == np.float32(wh.torque_limit) if prec == "float32" else np.abs(u) == wh.torque_limit))
        assert worst <= (float(np.float32(wh.torque_limit)) if prec == "float32" else wh.torque_limit)
        assert hits > 100           # the envelope reaches the saturation: the limit is exercised, not just unreached
        z_before = cc._zbuf.copy()
        for bad in (np.nan, np.inf):
            with pytest.raises(FloatingPointError, match="non-finite"):
                cc.command([0, 0, bad, 1], np.zeros(3), ctrl.Omega_ref)
            np.testing.assert_array_equal(cc._zbuf, z_before)


# ---------------------------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------------------------


def test_cli_export_c_json(capsys, tmp_path):
    require("cc")
    from lavendersim import cli

    out = tmp_path / "flight"
    code = cli.main(["lqr", "--spacecraft", "cubesat6u", "--export-c", str(out), "--json"])
    o, e = capsys.readouterr()
    assert code == 0, e
    x = json.loads(o)["export_c"]
    assert {p.name for p in out.iterdir()} >= {"controller.h", "controller.c", "main.c"}
    s = x["sil"]
    assert s["command_rel_f64"] <= 1e-12 and s["trajectory_diff_f64"] <= 1e-9 and s["settle_rel_f32"] <= 0.05
    assert s["command_diff_f32"] > 0 and s["ok"] is True
    assert x["compile_command"].startswith(("cc ", "gcc ")) or "-std=c99" in x["compile_command"]
    assert x["lines"]["controller.c"] > 100 and x["n_ops"] > 100
    # and the text form (the pyramid cube: 0.3 s of flight)
    code = cli.main(["lqr", "--spacecraft", "cube_pyramid4", "--no-noise", "--export-c", str(tmp_path / "t")])
    o, e = capsys.readouterr()
    assert code == 0, e
    assert "exported C99" in o and "SIL passed" in o and "bit-identical" in o


def test_cli_export_c_bad_directory_is_one_line(capsys, tmp_path):
    from lavendersim import cli

    (tmp_path / "f").write_text("x")
    code = cli.main(["lqr", "--spacecraft", "cubesat6u", "--export-c", str(tmp_path / "f" / "d")])
    o, e = capsys.readouterr()
    assert code == 2 and len(e.strip().splitlines()) == 1 and "--export-c" in e


# ---------------------------------------------------------------------------------------------
# the printer on every operation it knows
# ---------------------------------------------------------------------------------------------


def test_every_operation_prints_as_casadi_evaluates_it(tmp_path):
    """One SX Function using every operation the printer maps (arithmetic, comparisons, logic, if_else,
    libm functions), compiled and evaluated on random inputs: float64 equals CasADi's evaluation to 2 ulps
    (libm functions may round differently from the C++ standard library's; the arithmetic is exact)."""
    require("cc")
    import ctypes

    import casadi as ca

    from lavendersim import controller_c as CC
    from lavendersim.extending import compiler

    x = ca.SX.sym("x", 3)
    a, b, c = x[0], x[1], x[2]
    pos = ca.fabs(a) + 0.5
    unit = ca.tanh(b) * 0.9
    exprs = [a + b, a - b, a * b, a / pos, -a, a ** 2, 2 * a, 1 / pos, pos ** 2.5, pos ** b, ca.sqrt(pos), ca.exp(unit),
             ca.log(pos), ca.sin(a), ca.cos(a), ca.tan(unit), ca.asin(unit), ca.acos(unit), ca.atan(a), ca.atan2(a, b),
             ca.floor(a), ca.ceil(a), ca.fmod(a, pos), ca.fabs(a), ca.sign(a), ca.copysign(a, b), ca.fmin(a, b),
             ca.fmax(a, b), ca.erf(a), ca.sinh(unit), ca.cosh(unit), ca.tanh(a), ca.asinh(a), ca.acosh(pos + 1),
             ca.atanh(unit), ca.log1p(pos), ca.expm1(unit), ca.hypot(a, b), a < b, a <= b, a == b, a != b,
             ca.logic_not(a < b), ca.logic_and(a < b, b < c), ca.logic_or(a < b, b < c), ca.if_else(a < b, c, -c),
             ca.sign(a * 0)]
    fn = ca.Function("ops", [x], [ca.vertcat(*exprs)], ["x"], ["y"])
    ops = {fn.instruction_id(k) for k in range(fn.n_instructions())}
    assert len(ops) >= 40
    src = "#include <math.h>\n" + CC.function_c(fn, "ops") + CC.function_c(fn, "ops_f32", "float32")
    (tmp_path / "ops.c").write_text(src)
    cmd = [*compiler(), *CC.CFLAGS, "-fPIC", "-shared", "ops.c", "-o", "libops.so", "-lm"]
    r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, f"$ {' '.join(cmd)}\n{r.stdout}{r.stderr}"
    lib = ctypes.CDLL(str(tmp_path / "libops.so"))
    rng = np.random.default_rng(5)
    n = len(exprs)
    for prec, ct, dt, rtol in (("", ctypes.c_double, np.float64, 4.5e-16), ("_f32", ctypes.c_float, np.float32, 3e-6)):
        f = getattr(lib, "ops" + prec)
        f.argtypes = [ctypes.POINTER(ct)] * 2
        f.restype = None
        for _ in range(200):
            xv = rng.normal(size=3) * 2
            if rng.random() < 0.2:
                xv[1] = xv[0]                       # the equality branches
            y = np.zeros(n, dtype=dt)
            xin = np.ascontiguousarray(xv.astype(dt))
            f(xin.ctypes.data_as(ctypes.POINTER(ct)), y.ctypes.data_as(ctypes.POINTER(ct)))
            ref = np.asarray(fn(xin.astype(float))).ravel()
            np.testing.assert_allclose(y.astype(float), ref, rtol=rtol, atol=rtol * np.abs(ref).max() * (dt is np.float32))


def test_compiled_controller_copies_but_does_not_pickle(designs):
    """A copy shares the library and has its own memory (spacecraft.monte_carlo copies the controller it flies);
    pickling (another process) is refused with a reason."""
    require("cc")
    import copy
    import pickle

    from lavendersim import controller_c as CC

    ctrl = designs["cubesat6u"][1]
    k = CC.CompiledController(ctrl)
    k2 = copy.copy(k)
    q = np.array([0.1, 0.0, 0.0, 1.0]) / np.hypot(0.1, 1.0)
    u = k2.command(q, np.zeros(3), ctrl.Omega_ref)
    assert np.any(k2.z != k.z) and np.array_equal(u, CC.CompiledController(ctrl).command(q, np.zeros(3), ctrl.Omega_ref))
    with pytest.raises(TypeError, match="does not pickle"):
        pickle.dumps(k)
