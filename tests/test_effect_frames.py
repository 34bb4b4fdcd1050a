"""Body-frame torques and force-only bodies (issue 30): angular_damping declares its torque in the body frame
(tau_b = -c omega_b), so a plain body whose torques are all body-frame takes rigid_body_rhs_body_c on the effects'
body-frame forms (nothing rotated); a body whose effects declare no torque (gravity, linear damping) takes
rigid_body_rhs_force_c on a_w = F/m. Checked against hand integrations written here from the textbook equations
(not the printed kernels), and C = NumPy bitwise on every class and several integrators."""
from __future__ import annotations

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import effects as E
from lavendersim.generated import effects_meta

BACKENDS = ("c", "numpy")
I_BOX = (0.0333, 0.1133, 0.1333)


def _scene(n, effects, I=I_BOX, seed=0, per_body=()):
    rng = np.random.default_rng(seed)
    s = lv.Scene()
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    s.add_bodies([f"b{i}" for i in range(n)], np.full(n, 2.0), np.tile(I, (n, 1)), q=q,
                 omega_b=rng.standard_normal((n, 3)), v_w=rng.standard_normal((n, 3)))
    for name, p in effects:
        s.add_effect(name, **p)
    for b, name, p in per_body:
        s.add_effect(name, body=f"b{b}", **p)
    return s


def _quat_mul(a, b):
    """Hamilton product, (x, y, z, w) scalar last, of each row of a and b (shape (n, 4))."""
    av, aw, bv, bw = a[:, :3], a[:, 3:], b[:, :3], b[:, 3:]
    return np.concatenate([aw * bv + bw * av + np.cross(av, bv), aw * bw - np.sum(av * bv, axis=1, keepdims=True)],
                          axis=1)


def _rot(q):
    """The rotation matrix of each unit quaternion row (x, y, z, w), shape (n, 3, 3)."""
    x, y, z, w = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)], axis=1)


def _hand_rk4(x, m, I, g, c_lin, c_ang, dt, n):
    """RK4 of each body (a row of x, shape (bodies, 13)) from the textbook equations, torque in the WORLD frame
    rotated into the body: I w' = -w x (I w) + R^T tau_w with tau_w = -c_ang R w (what angular damping means),
    v' = g - c_lin v / m. The bodies are independent: each row is the one-body integration, the rows stepped
    together (NumPy over the body axis) only to be fast."""
    I = np.asarray(I, float)

    def f(y):
        q, v, w = y[:, 3:7], y[:, 7:10], y[:, 10:13]
        R = _rot(q / np.linalg.norm(q, axis=1, keepdims=True))
        tau_w = -c_ang * np.einsum("nij,nj->ni", R, w)
        wd = (np.einsum("nji,nj->ni", R, tau_w) - np.cross(w, I * w)) / I
        return np.concatenate([v, 0.5 * _quat_mul(q, np.pad(w, ((0, 0), (0, 1)))), g - c_lin * v / m, wd], axis=1)

    for _ in range(n):
        k1 = f(x)
        k2 = f(x + dt / 2 * k1)
        k3 = f(x + dt / 2 * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x[:, 3:7] /= np.linalg.norm(x[:, 3:7], axis=1, keepdims=True)
    return x


def test_flags_say_which_frame():
    meta = {e["name"]: e for e in effects_meta.EFFECTS}
    assert meta["angular_damping"]["flags"] & E.FLAG_TORQUE_B
    assert not meta["angular_damping"]["flags"] & E.FLAG_TORQUE_W
    assert meta["applied_torque"]["flags"] & E.FLAG_TORQUE_W
    assert not meta["gravity"]["flags"] & (E.FLAG_TORQUE_W | E.FLAG_TORQUE_B)
    flags = np.array([meta["gravity"]["flags"], meta["angular_damping"]["flags"],
                      meta["angular_damping"]["flags"] | meta["linear_damping"]["flags"],
                      meta["angular_damping"]["flags"] | meta["applied_torque"]["flags"]])
    assert E.rhs_classes(flags).tolist() == [E.RHS_FORCE, E.RHS_BODY, E.RHS_BODY_F, E.RHS_FULL]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("n", [1, 2, 9, 40])
def test_damping_and_gravity_match_a_hand_integration(backend, n):
    """gravity + linear + angular damping (class RHS_BODY_F; at n >= 2 the C effect tiles): the numbers of a hand RK4
    with the torque taken in the world frame and rotated back. A body-frame torque mistaken for a world one (or
    the reverse) is off by ~c |w| dt per step, far above this tolerance."""
    c_lin, c_ang, dt, steps = 0.05, 0.2, 1e-3, 300
    s = _scene(n, [("gravity", {}), ("linear_damping", {"c": c_lin}), ("angular_damping", {"c": c_ang})])
    sim = lv.Sim(s, dt=dt, integrator="rk4", backend=backend)
    x0 = np.array(sim.x)
    sim.run(steps)
    ref = _hand_rk4(x0, 2.0, I_BOX, np.array([0.0, 0.0, -9.81]), c_lin, c_ang, dt, steps)
    np.testing.assert_allclose(sim.x, ref, rtol=0, atol=1e-11)


@pytest.mark.parametrize("backend", BACKENDS)
def test_angular_damping_of_a_sphere_is_exponential(backend):
    """A sphere (k = 0) with angular damping: omega_b(t) = omega_b(0) exp(-c t / I) (RK4's error ~ (c dt / I)^5 / 120
    per step); its body-frame torque -c omega_b rotated by a wrong R would turn omega_b away from its axis."""
    c, I, dt, steps = 0.3, 0.2, 1e-3, 1000
    s = _scene(5, [("angular_damping", {"c": c})], I=(I, I, I), seed=3)
    sim = lv.Sim(s, dt=dt, integrator="rk4", backend=backend)
    w0 = np.array(sim.x)[:, 10:13]
    sim.run(steps)
    np.testing.assert_allclose(sim.x[:, 10:13], w0 * np.exp(-c * dt * steps / I), rtol=1e-12, atol=0)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("n", [1, 16])
def test_gravity_leaves_the_rotation_bitwise_a_plain_bodys(backend, n):
    """Force-only bodies (rigid_body_rhs_force_c): q and omega_b are bitwise those of the same bodies without
    gravity (no zero torque is rotated into them); v and p follow v0 + g t, p0 + v0 t + g t^2 / 2 (RK4 is exact on
    them)."""
    dt, steps = 1e-3, 200
    sims = [lv.Sim(_scene(n, effs, seed=5), dt=dt, integrator="rk4", backend=backend)
            for effs in ([], [("gravity", {})])]
    x0 = np.array(sims[1].x)
    for sim in sims:
        sim.run(steps)
    plain, grav = np.array(sims[0].x), np.array(sims[1].x)
    assert plain[:, 3:7].tobytes() == grav[:, 3:7].tobytes() and plain[:, 10:].tobytes() == grav[:, 10:].tobytes()
    t, g = dt * steps, np.array([0.0, 0.0, -9.81])
    np.testing.assert_allclose(grav[:, 7:10], x0[:, 7:10] + g * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(grav[:, 0:3], x0[:, 0:3] + x0[:, 7:10] * t + g * t * t / 2, rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("n", [1, 16])
def test_a_constant_torque_leaves_the_translation_bitwise_a_plain_bodys(backend, n):
    """Bodies whose effects read no state stage only (q, omega_b) (csrc/step.c lv_const_rk4_h): a constant world
    torque leaves p and v bitwise those of the same bodies without it (p by translation_drift, v kept), and gravity
    added to it leaves q and omega_b bitwise the torque-only bodies' (its translation by the printed exact flow)."""
    dt, steps = 1e-3, 200
    torque = ("applied_torque", {"torque_w": [0.3, -0.2, 0.5]})
    sims = [lv.Sim(_scene(n, effs, seed=7), dt=dt, integrator="rk4", backend=backend)
            for effs in ([], [torque], [torque, ("gravity", {})])]
    x0 = np.array(sims[2].x)
    for sim in sims:
        sim.run(steps)
    plain, tq, both = (np.array(sim.x) for sim in sims)
    assert plain[:, 0:3].tobytes() == tq[:, 0:3].tobytes() and plain[:, 7:10].tobytes() == tq[:, 7:10].tobytes()
    assert tq[:, 3:7].tobytes() == both[:, 3:7].tobytes() and tq[:, 10:].tobytes() == both[:, 10:].tobytes()
    assert plain[:, 10:].tobytes() != tq[:, 10:].tobytes()     # the torque acts
    t, g = dt * steps, np.array([0.0, 0.0, -9.81])
    np.testing.assert_allclose(both[:, 7:10], x0[:, 7:10] + g * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(both[:, 0:3], x0[:, 0:3] + x0[:, 7:10] * t + g * t * t / 2, rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_the_doubled_torque_stage_is_the_rotated_torques_bitwise(backend):
    """rigid_body_increments_torque_h takes the world torque with its double (rigid_body_torque_constants, once per
    call: t = q_v x (2 tau) where rotate_to_body forms (2 q_v) x tau at each stage): its rows are bitwise
    rigid_body_increments_torque_c's (q, omega_b) rows, over torques of 1e-150 to 1e150 (subnormal and huge products
    included), stage quaternions that are not unit, and signed zeros."""
    from lavendersim.backends import c_backend
    from lavendersim.generated import kernels_numpy as KN
    call = (lambda name, *a: c_backend.eval_kernel(name, *a)) if backend == "c" else (
        lambda name, *a: KN.KERNELS[name][0](*a))
    rng = np.random.default_rng(30)
    n = 4000
    q = rng.standard_normal((n, 4)) * (1.0 + 1e-3 * rng.standard_normal((n, 1)))
    w = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-3, 3, (n, 1))
    v, S = rng.standard_normal((n, 3)), rng.standard_normal((n, 9))
    tau = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-150, 150, (n, 1))
    q[::7, 1], q[::11, 3], tau[::5, 2], tau[::13, 0] = 0.0, -0.0, -0.0, 0.0
    Hq, Hw = call("rigid_body_increments_torque_h", q, w, S, call("rigid_body_torque_constants", tau))
    H = call("rigid_body_increments_torque_c", q, w, v, S, tau)
    assert np.isfinite(H).all()
    assert Hq.tobytes() == np.ascontiguousarray(H[:, 3:7]).tobytes()
    assert Hw.tobytes() == np.ascontiguousarray(H[:, 10:13]).tobytes()


SETS = {
    "gravity": [("gravity", {})],
    "applied torque": [("applied_torque", {"torque_w": [1e-3, 2e-3, -1e-3]})],
    "gravity + applied torque": [("gravity", {}), ("applied_torque", {"torque_w": [1e-3, 2e-3, -1e-3]})],
    "angular damping": [("angular_damping", {"c": 2e-3})],
    "damping": [("linear_damping", {"c": 0.05}), ("angular_damping", {"c": 2e-3})],
    "gravity + damping": [("gravity", {}), ("linear_damping", {"c": 0.05}), ("angular_damping", {"c": 2e-3})],
    "torque + damping": [("applied_torque", {"torque_w": [1e-3, 2e-3, -1e-3]}), ("angular_damping", {"c": 2e-3})],
    "torque + linear and angular damping": [("applied_torque", {"torque_w": [1e-3, 2e-3, -1e-3]}),
                                            ("linear_damping", {"c": 0.05}), ("angular_damping", {"c": 2e-3})],
    "force at point + damping": [("force_at_point", {"r_b": [0.1, -0.05, 0.02], "F_w": [0.3, 0.0, -1.0]}),
                                 ("angular_damping", {"c": 2e-3})],
}


@pytest.mark.parametrize("integrator", ["rk4", "euler", "dopri5"])
@pytest.mark.parametrize("name", sorted(SETS))
def test_c_equals_numpy_bitwise_on_every_class(integrator, name):
    """Every right-hand side class (scene-wide effects, and a mix of classes: body 0 with its own world torque) on
    both backends: the same bits (tobytes: the signs of zeros too), at N = 1 (numpy's float path), 3 and 37 (tiles)."""
    for n in (1, 3, 37):
        per_body = [(0, "applied_torque", {"torque_w": [0.1, 0.0, 0.0]}), (n - 1, "gravity", {})] if n > 1 else []
        out = []
        for backend in BACKENDS:
            sim = lv.Sim(_scene(n, SETS[name], seed=n, per_body=per_body), dt=1e-3, integrator=integrator,
                         backend=backend)
            sim.run(40)
            out.append(np.array(sim.x))
        assert out[0].tobytes() == out[1].tobytes(), (name, n, np.max(np.abs(out[0] - out[1])))
