"""What Sim.pipeline names: the printed kernels a plain body's step runs, per backend, dtype and path (printed into
generated/effects_meta.py as PIPELINE_KERNELS; lavendersim/pipeline.py picks a body's path and reads its row).

A row is (what, kernels) pairs, what one of the words a pipeline line prints. Its key is "<how>:<path>", and
"float32:<how>:<path>" for single precision:
- how "rk4": the built-in RK4's scaled-increment paths (_rk4_paths); "rhs": a right-hand side that an explicit
  tableau (euler, semi_implicit_euler, a user's; rk4 where it has no scaled path) steps (_rhs_paths); "dopri5" where
  it differs from "rhs"; an integrator of the implicit or the Lie-group family by its name (_family_paths);
- a body with a joint or wheels: "<integrator>:model_rotation:<rot>" (a user's tableau: "tableau:model_rotation:<rot>")
  and "model_translation:<trans>" (_model_paths);
- path FREE (no effect), a right-hand-side kind (effect_fuse.TILE_KINDS), CONST_<kind> / SPLIT_<kind> (RK4's
  constant and decoupled paths); float32: FREE, CONST_TORQUE / CONST_FORCE (every effect reads no state, without /
  with a force) and ANY, csrc/fixed_loop.h's LV_FIXED_* tiles (_float32_paths).
Every name is a kernel of generated/kernels.h; tests/test_sim_pipeline.py checks the rows against the kernels the
NumPy backend calls and the C sources call."""
from __future__ import annotations

from .effect_fuse import CONSTANT_KINDS, RHS_OF_KIND, SPLIT_OF_KIND, TILE_KINDS
from .layout import WHEELS_MAX
from .tableaux import INTEGRATORS, fixed_path

Row = tuple[tuple[str, tuple[str, ...]], ...]

# Sim.pipeline's words for the parts of a plain body's step
_STAGES_ROT, _STAGES_ALL, _TRANSLATION, _CONSTANTS, _RHS = ("stages (q, omega_b)", "stages (13 numbers)", "translation",
                                                            "constants", "right-hand side")
_RHS_ONCE = "right-hand side (loads summed once per call)"


def _rk4_paths(backend: str) -> dict[str, Row]:
    """The built-in RK4's paths of a plain body on backend ("c" or "numpy") and the printed kernels each runs: FREE
    (no effect: csrc/step.c lv_free_rk4_h, numpy_backend._free_rk4_h), CONST_<kind> (every effect reads no state,
    CONSTANT_KINDS: lv_const_rk4_h, _const_rk4_h), SPLIT_<kind> (decoupled, SPLIT_OF_KIND: LV_SPLIT_RK4_H,
    _split_rk4_h), <kind> (the 13-number stages on the kind's increments: plain_inc, _forced_rk4_h)."""
    free = ("rigid_body_increments_free_c",)
    out: dict[str, Row] = {
        "FREE": ((_STAGES_ROT, free), (_TRANSLATION, ("translation_drift",)),
                 (_CONSTANTS, ("rigid_body_increment_scale_free",)))}
    for kind, (torque, force) in CONSTANT_KINDS.items():
        # C takes the torque-free constants from rigid_body_increment_scale's S (lv_const_scale), NumPy from
        # rigid_body_increment_scale_free (_free_scale): the same bits
        scale = "rigid_body_increment_scale" if torque or backend == "c" else "rigid_body_increment_scale_free"
        out[f"CONST_{kind}"] = (
            (_STAGES_ROT, ("rigid_body_increments_torque_h",) if torque else free),
            (_TRANSLATION, ("translation_flow_constant",) if force else ("translation_drift",)),
            (_CONSTANTS, (scale,) + (("rigid_body_torque_constants",) if torque else ())
             + (("constant_acceleration_steps",) if force else ())))
    for kind, split in SPLIT_OF_KIND.items():
        if split:
            out[f"SPLIT_{kind}"] = (
                (_STAGES_ROT, free if split == 1 else ("rigid_body_increments_rot_b_c",)),
                (_TRANSLATION, ("translation_flow",)),
                (_CONSTANTS, ("rigid_body_increment_scale", "translation_flow_scale")))
    for kind in TILE_KINDS:
        # the NumPy backend runs TORQUE on FULL's kernels (effects.RHS_FULL): bitwise the same on a zero force
        inc = RHS_OF_KIND["FULL" if kind == "TORQUE" and backend == "numpy" else kind].inc[0]
        out[kind] = ((_STAGES_ALL, (inc,)), (_CONSTANTS, ("rigid_body_increment_scale",)))
    return out


def _rhs_paths(backend: str) -> dict[str, Row]:
    """A plain body's right-hand side on backend: FREE, and each kind's (RHS_OF_KIND; csrc/step.c body_rhs,
    plain_rhs; numpy_backend _Plan.rhs, _ForcedGroup.rhs)."""
    out: dict[str, Row] = {"FREE": ((_RHS, ("rigid_body_rhs_free" if backend == "c" else "rigid_body_rhs_free_c",)),)}
    for kind in TILE_KINDS:
        r = RHS_OF_KIND["FULL" if kind == "TORQUE" and backend == "numpy" else kind]
        out[kind] = ((_RHS, (("linear_acceleration",) if r.accel else ()) + (r.kernel,)),)
    return out


# The step of each integrator family that runs kernels of its own, beside the right-hand side or the loads:
# implicit (csrc/step.c gyro_step, numpy_backend._implicit_gyro: the loads at the step's start, omega_1 by Newton,
# q <- q (x) exp(h omega_1 / 2), then v, p), lie_group_rk (step.c rk4_expmap_step / expmap_stage,
# numpy_backend._step_rk4_expmap: each stage's attitude q0 (x) exp(u/2) and u' = dexp^-1(u) omega on the RK4 tableau
# over the right-hand side).
_FAMILY_PARTS: dict[str, Row] = {
    "implicit": (("rotation (Newton solve, exp-map update)", ("implicit_gyro_newton", "quat_exp_step")),
                 (_TRANSLATION, ("semi_implicit_translation",))),
    "lie_group_rk": (("exponential coordinates", ("quat_exp_step", "rkmk_dexpinv")),),
}
_LOADS = ("loads (at the step's start)", ("world_to_body",))   # step.c plain_loads, numpy _Plan.loads
# The partitioned (symplectic) Euler step's positions after its rates (csrc/step.c advance_block, fixed_loop.h
# body_step, numpy_backend._step_semi_implicit_euler: p + dt v', q + dt q'(omega'))
_SEMI_IMPLICIT = ("positions (with the new rates)", ("translation_drift", "quat_derivative_body"))


def _family_paths(backend: str) -> dict[str, Row]:
    """The rows "<integrator>:<path>" of the integrators that run kernels of their own, path FREE or a kind: the
    partitioned Euler step (fixed path semi_implicit) its right-hand side and positions; the implicit family the
    loads (bodies with effects) and its own step; lie_group_rk the kind's right-hand side (the same body_rhs /
    _Plan.rhs as rhs:<path>) and its exponential coordinates."""
    rhs = _rhs_paths(backend)
    out: dict[str, Row] = {}
    for i in INTEGRATORS:
        if fixed_path(i) == "semi_implicit":
            for path in ("FREE",) + TILE_KINDS:
                out[f"{i.name}:{path}"] = rhs[path] + (_SEMI_IMPLICIT,)
        elif i.family == "implicit":
            for path in ("FREE",) + TILE_KINDS:
                out[f"{i.name}:{path}"] = (() if path == "FREE" else (_LOADS,)) + _FAMILY_PARTS[i.family]
        elif i.family == "lie_group_rk":
            for path in ("FREE",) + TILE_KINDS:
                out[f"{i.name}:{path}"] = rhs[path] + _FAMILY_PARTS[i.family]
        elif i.family not in ("explicit_rk", "adaptive_rk", "composition"):
            raise RuntimeError(f"derive: integrator {i.name}: family {i.family!r} has no Sim.pipeline row "
                               "(derive/pipeline_meta.py)")
    return out


def _float32_paths(backend: str) -> dict[str, Row]:
    """Single precision (csrc/fixed_loop.h; numpy_backend on a float32 plan): the torque-free RK4 on the scaled
    increments as in float64 ("rk4:FREE"), every other step on a right-hand side of the coefficient form. fixed_loop.h
    tiles bodies by LV_FIXED_*: FREE rigid_body_rhs_free_c; CONST_TORQUE (no effect reads the state, none adds a
    force) rigid_body_rhs_torque_c and CONST_FORCE rigid_body_rhs_c, on the loads summed once per call; ANY
    rigid_body_rhs_c, the loads summed at every stage. The NumPy backend steps every body with effects on FULL's
    rigid_body_rhs_c (numpy_backend._forced_groups), summing at every stage: the same bits."""
    once = _RHS_ONCE if backend == "c" else _RHS
    rhs: dict[str, Row] = {
        "FREE": ((_RHS, ("rigid_body_rhs_free_c",)),),
        "CONST_TORQUE": ((once, ("rigid_body_rhs_torque_c" if backend == "c" else "rigid_body_rhs_c",)),),
        "CONST_FORCE": ((once, ("rigid_body_rhs_c",)),),
        "ANY": ((_RHS, ("rigid_body_rhs_c",)),)}
    out = {"rk4:FREE": _rk4_paths(backend)["FREE"]} | {f"rhs:{k}": v for k, v in rhs.items()}
    for i in INTEGRATORS:
        if i.float32 and fixed_path(i) == "semi_implicit":
            out.update({f"{i.name}:{k}": v + (_SEMI_IMPLICIT,) for k, v in rhs.items()})
    return out


def _model_paths(backend: str) -> dict[str, Row]:
    """A body with a joint or wheels (csrc/step.c model_rhs_of, advance_model, model_simd.h; numpy_backend _Group,
    _Plan.rhs): its rotation, rot WHEELS_ON_AXES (wheels on the default layout A_b = [I | 0]), WHEELS (other axes) or
    PIVOT (a joint alone), per integrator that steps such bodies: on C the fixed-step paths (euler,
    semi_implicit_euler, rk4: lv_step_kind adds LV_ON_AXES) take the on-axes print for WHEELS_ON_AXES, the stage loop
    (dopri5, a user's tableau: ctx_init's row kind) the general one; NumPy wheels<N>_body_rhs for every layout. With
    wheels, the motors per step (zero-order hold) and, on C, the coefficients once per call. Its translation, trans
    FREE (translation_rhs), JOINT (p_w, v_w from pivot_kinematics after each step; NumPy also forms the group's
    translation_rhs and zeroes it) or JOINT_V (pivot_kinematics in the right-hand side too, for effects that read
    v_w)."""
    n = WHEELS_MAX
    motor = ("wheel motors (per step, zero-order hold)", (f"wheels{n}_motor",))
    coefficients = (("constants", (f"wheels{n}_coefficients",)),) if backend == "c" else ()
    out: dict[str, Row] = {}
    steppers = [(i.name, fixed_path(i) is not None) for i in INTEGRATORS if not i.plain_only] + [("tableau", False)]
    for name, fixed in steppers:
        general = f"wheels{n}_body_rhs_c" if backend == "c" else f"wheels{n}_body_rhs"
        on_axes = f"wheels{n}_on_axes_rhs_c" if backend == "c" and fixed else general
        for rot, kernel in (("WHEELS_ON_AXES", on_axes), ("WHEELS", general)):
            out[f"{name}:model_rotation:{rot}"] = (("rotation and wheels", (kernel,)), motor) + coefficients
        out[f"{name}:model_rotation:PIVOT"] = (("rotation about the pivot", ("pivot_body_rhs",)),)
    # (NumPy forms translation_rhs for a whole group, wheeled and jointed bodies together, and zeroes a jointed
    # body's: numpy_backend._Group.translation)
    joint = ("pivot_kinematics",) if backend == "c" else ("pivot_kinematics", "translation_rhs")
    zeroed = "" if backend == "c" else ", the group's translation_rhs zeroed"
    out["model_translation:FREE"] = ((_TRANSLATION, ("translation_rhs",)),)
    out["model_translation:JOINT"] = ((f"translation (p_w, v_w set from the joint after each step{zeroed})", joint),)
    out["model_translation:JOINT_V"] = ((f"translation (p_w, v_w set from the joint after each step, v_w for the "
                                         f"effects that read it{zeroed})", joint),)
    return out


def pipeline_kernels() -> dict[str, dict[str, Row]]:
    """The printed kernels a plain body's step runs, per backend ("c", "numpy") and key (the module's docstring).
    Printed into effects_meta (PIPELINE_KERNELS)."""
    out = {}
    for backend in ("c", "numpy"):
        table = {f"rk4:{k}": v for k, v in _rk4_paths(backend).items()}
        table.update({f"rhs:{k}": v for k, v in _rhs_paths(backend).items()})
        if backend == "c":   # C's dopri5 steps a torque-free body on rigid_body_rhs_free_c (csrc/step.c dp_rhs)
            table["dopri5:FREE"] = ((_RHS, ("rigid_body_rhs_free_c",)),)
        table.update(_family_paths(backend))
        table.update(_model_paths(backend))
        table.update({f"float32:{k}": v for k, v in _float32_paths(backend).items()})
        out[backend] = table
    return out
