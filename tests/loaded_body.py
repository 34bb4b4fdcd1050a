"""The loaded body the high-order integrator tests measure orders on (test_highorder, test_symtop): one box with a
world-fixed torque, gravity and optionally angular damping, and its errors against a dopri5 reference."""
from __future__ import annotations

import numpy as np

import lavendersim as lv
from lavendersim import oracle as R

W0 = (1.0, 0.5, 0.2)   # its initial omega_b (the accuracy lab's diag_w1)


def loaded(integrator, dt, damping=None, backend="c", **kw):
    """The loaded body's Sim: torque_w = [0.3, -0.1, 0.2], gravity, angular damping c = `damping` (None: none)."""
    effects = [("applied_torque", {"torque_w": [0.3, -0.1, 0.2]}), ("gravity", {"g_w": [0, 0, -9.81]})]
    if damping is not None:
        effects.append(("angular_damping", {"c": damping}))
    scene = lv.Scene()
    scene.add_body(lv.Body("b", 1.0, (1.0, 2.0, 2.5), omega_b=W0, v_w=(0.1, 0.0, 0.0)))
    for name, params in effects:
        scene.add_effect(name, **params)
    return lv.Sim(scene, dt=dt, integrator=integrator, backend=backend, **kw)


def loaded_errors(integrator, damping, exps, backend) -> np.ndarray:
    """The largest of the attitude, omega_b and p_w errors at T = 4 s against dopri5 at rtol 1e-13, per dt = 2**-k."""
    T_end = 4.0
    ref = loaded("dopri5", 0.5, damping, backend, rtol=1e-13, atol=1e-13)
    ref.run(8)
    out = []
    for k in exps:
        dt = 2.0 ** -k
        s = loaded(integrator, dt, damping, backend)
        s.run(int(round(T_end / dt)))
        out.append(max(float(R.attitude_error(s.x[0, 3:7], ref.x[0, 3:7])),
                       float(np.linalg.norm(s.x[0, 10:13] - ref.x[0, 10:13])),
                       float(np.linalg.norm(s.x[0, 0:3] - ref.x[0, 0:3]))))
    return np.asarray(out)
