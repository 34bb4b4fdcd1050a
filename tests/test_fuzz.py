"""Property-based fuzz of every public input (issue 11): Body / Scene / Sim / env / viewer payloads
driven with arbitrary values — floats including nan, ±inf, ±1e308, subnormals and negatives, wrong
shapes, wrong types (str, bytes, None, bool, complex, dict, object), unknown keywords.

Asserted for every call: only LavenderInputError (or DivergenceError while stepping) escapes, and a
rejected call leaves everything as it was (the scene's bodies and effects, the Sim's state, step
count and time, the env's simulator and random generator, the viewer's published frames).
What is accepted is also checked: a Body's numbers are finite and physical, an accepted overlay
draws within float32 range.

Hypothesis is a test dependency only (the package never imports it). Derandomized (a fixed seed:
the same examples on every run), no per-example deadline and no "too slow" health check (a loaded
machine must not fail a test), a bounded number of examples per property: the whole module runs in
well under a minute.
"""
from __future__ import annotations

import math
import os
import pickle
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import lavendersim as lv
from lavendersim import backends
from lavendersim import viewer as VW
from lavendersim.errors import DivergenceError
from lavendersim.validate import LavenderInputError

from conftest import have

FUZZ = settings(derandomize=True, deadline=None, max_examples=300,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])
FUZZ_SLOW = settings(FUZZ, max_examples=150)   # properties that build a Sim / env / live frame per example

SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, 2.0, 1e-308, 5e-324, -5e-324, 1e308, -1e308, 1.7976931348623157e308, 9e307,
           1e200, -1e200, 1e300, 1e154, 3.4e38, 1e39, math.nan, math.inf, -math.inf]

reals = st.one_of(st.sampled_from(SPECIAL), st.floats(), st.floats(-10, 10), st.integers(-2 ** 70, 2 ** 70),
                  st.sampled_from([np.float32(1.5), np.int8(3), np.float64(-2.0), np.float16(np.inf)]))
junk = st.one_of(st.none(), st.booleans(), st.text(max_size=4), st.complex_numbers(max_magnitude=1e10),
                 st.binary(max_size=2), st.just(object()), st.just([]), st.just({}), st.just({"x": 1}),
                 st.sampled_from([np.bool_(True), np.complex128(1j), np.array("ab"), np.array(None)]))
scalars = st.one_of(reals, reals, reals, junk)
nice = st.floats(-5, 5)


def vectors(n: int):
    """Mostly the right length, sometimes valid, often not: wrong lengths, nesting, dtypes, junk."""
    return st.one_of(
        st.lists(nice, min_size=n, max_size=n),
        st.lists(nice, min_size=n, max_size=n).map(np.array),
        st.lists(reals, min_size=n, max_size=n),
        st.lists(scalars, min_size=n, max_size=n).map(tuple),
        st.lists(scalars, min_size=0, max_size=n + 2),
        hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64, np.complex128, np.bool_, np.uint8]),
                   hnp.array_shapes(min_dims=0, max_dims=2, max_side=n + 1)),
        st.lists(st.lists(reals, min_size=1, max_size=3), min_size=1, max_size=3),
        scalars,
    )


valid_moments = st.tuples(st.floats(0.5, 2), st.floats(0.5, 2), st.floats(0.5, 2))
moments = st.one_of(valid_moments, valid_moments, valid_moments,
                    vectors(3), st.lists(st.lists(reals, min_size=3, max_size=3), min_size=3, max_size=3),
                    hnp.arrays(np.float64, (3, 3), elements=st.sampled_from(SPECIAL)))
shapes = st.one_of(st.none(), st.tuples(st.sampled_from(["box", "cylinder", "sphere", "cone", ""]), vectors(3)),
                   st.tuples(st.sampled_from(["sphere"]), scalars), scalars, st.lists(scalars, max_size=3))
names = st.one_of(st.sampled_from(["c", "x/y", "x_y", "b"]), st.sampled_from(["d", "e", "a"]), st.text(max_size=6), junk)
OK = (LavenderInputError,)
STEPPING_OK = (LavenderInputError, DivergenceError)


def nice_vectors(n: int):
    return st.lists(nice, min_size=n, max_size=n)


@st.composite
def perturbed(draw, valid, arbitrary: dict, unknown=("omega", "shap", "colour", "spin")):
    """A valid keyword dict with 0, 1 or 2 entries replaced by arbitrary values (or an unknown keyword
    added): each validator is reached alone as well as in combination, and many calls are accepted."""
    kw = dict(draw(valid))
    for _ in range(draw(st.sampled_from([0, 1, 1, 1, 2]))):
        key = draw(st.sampled_from(sorted(arbitrary) + ["<unknown>"]))
        if key == "<unknown>":
            kw[draw(st.sampled_from(unknown))] = draw(scalars)
        else:
            kw[key] = draw(arbitrary[key])
    return kw


valid_shapes = st.one_of(st.none(), st.tuples(st.just("box"), st.lists(st.floats(0.01, 2), min_size=3, max_size=3)),
                         st.tuples(st.just("sphere"), st.floats(0.01, 2)))


def body_kwargs():
    valid = st.fixed_dictionaries(
        {"name": st.sampled_from(["c", "x/y", "x_y", "d"]), "mass": st.floats(0.1, 10), "inertia": valid_moments},
        optional={"p_w": nice_vectors(3), "q": nice_vectors(4), "v_w": nice_vectors(3), "omega_b": nice_vectors(3),
                  "shape": valid_shapes})
    return perturbed(valid, {"name": names, "mass": scalars, "inertia": moments, "p_w": vectors(3), "q": vectors(4),
                             "v_w": vectors(3), "omega_b": vectors(3), "omega_w": vectors(3), "shape": shapes})


def _body_ok(b: lv.Body) -> None:
    """What an accepted Body holds: finite, physical, normalized, immutable."""
    assert isinstance(b.name, str) and b.name
    assert math.isfinite(b.mass) and b.mass > 0
    m = b.I_b
    assert m.shape == (3,) and np.all(np.isfinite(m)) and np.all(m > 0)
    assert b.x0.shape == (13,) and np.all(np.isfinite(b.x0))
    assert abs(np.linalg.norm(b.x0[3:7]) - 1.0) < 1e-12
    assert not b.I_b.flags.writeable and not b.x0.flags.writeable
    if b.shape is not None:
        kind, dims = b.shape
        assert kind in ("box", "cylinder", "sphere") and all(math.isfinite(d) and d > 0 for d in dims)


def _quiet(fn, *args, **kwargs):
    """Call with numpy's floating-point warnings silenced (an overflow inside a run that then raises
    DivergenceError is the run's business); exceptions pass through."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args, **kwargs)


# ---------------------------------------------------------------- Body ------------------------------------------------
@FUZZ
@given(kw=body_kwargs())
def test_fuzz_body(kw):
    try:
        b = _quiet(lv.Body, **kw)
    except OK as exc:
        event(f"rejected: {exc.field}")
        return
    event("accepted")
    _body_ok(b)


@FUZZ
@given(kind=st.sampled_from(["box", "cylinder", "sphere"]), mass=st.one_of(st.floats(0.1, 10), scalars),
       dims=st.lists(st.one_of(st.floats(0.01, 2), scalars), min_size=3, max_size=3),
       state=st.dictionaries(st.sampled_from(["q", "omega_b", "p_w", "shape", "spin"]), vectors(4), max_size=2))
def test_fuzz_body_constructors(kind, mass, dims, state):
    make = {"box": lambda: lv.Body.box("b", mass, dims, **state),
            "cylinder": lambda: lv.Body.cylinder("b", mass, dims[0], dims[1], **state),
            "sphere": lambda: lv.Body.sphere("b", mass, dims[0], **state)}[kind]
    try:
        b = _quiet(make)
    except OK:
        return
    _body_ok(b)


# ---------------------------------------------------------------- Scene + Sim -----------------------------------------
EFFECT_PARAMS = {
    "applied_torque": {"torque_w": vectors(3)},
    "force_at_point": {"r_b": vectors(3), "F_w": vectors(3)},
    "gravity": {"g_w": vectors(3)},
    "linear_damping": {"c": scalars},
    "angular_damping": {"c": scalars},
    "spherical_joint": {"anchor_w": vectors(3)},
    "reaction_wheels": {"J": vectors(3), "torque_limit": vectors(3), "speed_limit": vectors(3), "c_w": vectors(3)},
}


VALID_PARAMS = {
    "applied_torque": {"torque_w": nice_vectors(3)},
    "force_at_point": {"r_b": nice_vectors(3), "F_w": nice_vectors(3)},
    "gravity": {"g_w": nice_vectors(3)},
    "linear_damping": {"c": st.floats(0, 2)},
    "angular_damping": {"c": st.floats(0, 2)},
    "spherical_joint": {"anchor_w": nice_vectors(3)},
    "reaction_wheels": {"J": st.lists(st.floats(1e-4, 1e-2), min_size=3, max_size=3),
                        "torque_limit": st.lists(st.floats(0.01, 1), min_size=3, max_size=3),
                        "speed_limit": st.lists(st.floats(1, 500), min_size=3, max_size=3),
                        "c_w": st.lists(st.floats(0, 0.01), min_size=3, max_size=3)},
}


@st.composite
def effect_calls(draw):
    name = draw(st.one_of(st.sampled_from(sorted(EFFECT_PARAMS)), st.sampled_from(["gravty", "applied_torque"])))
    params = draw(perturbed(st.fixed_dictionaries(VALID_PARAMS.get(name, {})), EFFECT_PARAMS.get(name, {}),
                            unknown=("bogus", "torque", "g")))
    body = draw(st.one_of(st.sampled_from(["a", "b", "a", "b", None, "nobody"]), junk))
    return name, body, params


def _snapshot_scene(s: lv.Scene):
    return list(s.bodies.items()), list(s.effects)


def _snapshot_sim(sim: lv.Sim):
    m = sim._models
    return (sim.x.copy(), sim.steps, sim.t, sim.rhs_evals, m.Omega.copy(), m.command.copy())


def _same_sim(a, b) -> bool:
    return (np.array_equal(a[0], b[0], equal_nan=True) and a[1:4] == b[1:4]
            and np.array_equal(a[4], b[4], equal_nan=True) and np.array_equal(a[5], b[5], equal_nan=True))


BACKENDS = ["numpy"] + ([] if backends.c_unavailable() else ["c"])


@FUZZ_SLOW
@given(calls=st.lists(st.one_of(effect_calls(), body_kwargs().map(lambda kw: ("body", kw))), max_size=4),
       sim_kw=perturbed(st.fixed_dictionaries(
           {"dt": st.sampled_from([1e-3, 1e-2, 0.1, 1.0]),
            "integrator": st.sampled_from(["rk4", "euler", "semi_implicit_euler", "splitting", "implicit_gyro", "dopri5"]),
            "backend": st.sampled_from(BACKENDS)}),
           {"dt": scalars, "integrator": scalars, "backend": scalars, "normalize": scalars, "rtol": scalars,
            "atol": scalars}, unknown=("steps", "integrater", "seed")),
       n=st.integers(0, 20),
       state=perturbed(st.fixed_dictionaries({}, optional={
           "omega_b": st.sampled_from([(1e200, 0, 0), (0, 3e3, 1), (1e150, 1e150, 0), (0.1, 2, 0), (1e6, 0, 1)]),
           "q": st.sampled_from([(0, 0, 0, 1), (0.1, 0.2, 0.3, 0.9), (1, 0, 0, 0)])}),
                       {"omega_b": vectors(3), "q": vectors(4), "p_w": vectors(3), "v_w": vectors(3),
                        "omega_w": vectors(3), "Omega": vectors(3)}, unknown=("w", "omega")))
def test_fuzz_scene_and_sim(calls, sim_kw, n, state):
    s = lv.Scene()
    s.add_body(lv.Body.box("a", 1.0, (0.3, 0.2, 0.1), omega_b=(0.1, 2.0, 0.1)))
    s.add_body(lv.Body("b", 2.0, (1.0, 1.5, 2.0), p_w=(1, 0, 0)))
    for kind, body, *params in [(c[0], c[1], *c[2:]) for c in calls]:
        before = _snapshot_scene(s)
        try:
            if kind == "body":
                _quiet(lambda: s.add_body(lv.Body(**body)))
            else:
                _quiet(s.add_effect, kind, body=body, **params[0])
            event(f"add {kind}: accepted")
        except OK:
            event(f"add {kind}: rejected")
            assert _snapshot_scene(s) == before, "a rejected add changed the scene"
    try:
        sim = _quiet(lv.Sim, s, **sim_kw)
    except OK:
        event("Sim rejected")
        return
    event(f"Sim built ({sim.integrator}, {sim.backend.name})")
    snap = _snapshot_sim(sim)
    name = "a"
    try:
        _quiet(sim.set_state, name, **state)
    except OK:
        assert _same_sim(_snapshot_sim(sim), snap), "a rejected set_state changed the Sim"
    if sim.integrator in ("dopri5",) and not sim.dt <= 0.1:
        return                          # adaptive: up to 1e6 substeps per output step; not a fuzz target
    snap = _snapshot_sim(sim)
    try:
        _quiet(sim.run, n)
        event("run: ok")
    except DivergenceError:
        event("run: DivergenceError")
        assert _same_sim(_snapshot_sim(sim), snap), "DivergenceError left the Sim changed"
    except OK:
        event("run: rejected")
        assert _same_sim(_snapshot_sim(sim), snap), "a rejected run changed the Sim"


# ---------------------------------------------------------------- env -------------------------------------------------
@pytest.fixture(scope="module")
def cube_env():
    if not have("gym"):
        pytest.skip("gym extra not installed (pip install 'lavendersim[gym]')")
    import gymnasium as gym

    env = gym.make("lavendersim:ReactionWheelCube-v0", backend="numpy").unwrapped
    env.reset(seed=0)
    return env


@FUZZ_SLOW
@given(action=vectors(3), options=st.one_of(st.none(), scalars, st.dictionaries(
    st.sampled_from(["q", "omega_b", "Omega", "spin"]), vectors(4), max_size=2)),
    seed=st.one_of(st.none(), st.integers(-5, 2 ** 64 + 5), scalars))
def test_fuzz_env(cube_env, action, options, seed):
    env = cube_env
    sim, rng = env.sim, env.np_random.bit_generator.state
    snap = _snapshot_sim(sim)
    try:
        _quiet(env.step, action)
        event("step: accepted")
    except OK:
        event("step: rejected")
        assert _same_sim(_snapshot_sim(env.sim), snap), "a rejected action changed the simulator"
    try:
        _quiet(env.reset, seed=seed, options=options)
    except OK:
        assert env.sim is sim and env.np_random.bit_generator.state == rng, "a rejected reset changed the env"
        return
    assert np.all(np.isfinite(env.sim.x))


@FUZZ
@given(kw=st.dictionaries(st.sampled_from(["task", "render_mode", "dt", "control_dt", "damping", "init_angle_deg",
                                           "max_tilt_deg", "target_q", "mass", "J", "speed_limt", "model"]),
                          st.one_of(st.sampled_from(["center", "corner", "human", "rgb_array", "rgb_array_list"]),
                                    vectors(4)), max_size=3))
def test_fuzz_env_constructor(cube_env, kw):
    from lavendersim.envs.reaction_wheel_cube import ReactionWheelCubeEnv

    try:
        env = _quiet(ReactionWheelCubeEnv, backend="numpy", **kw)
    except OK:
        return
    assert env.render_mode in (None, "rgb_array")


# ---------------------------------------------------------------- viewer ----------------------------------------------
def overlay_payloads():
    valid_vec = st.fixed_dictionaries({"origin": nice_vectors(3), "vector": nice_vectors(3)},
                                      optional={"label": st.text(max_size=8), "scale": st.floats(0.01, 10),
                                                "color": st.lists(st.floats(0, 1), min_size=4, max_size=4)})
    vec = st.one_of(valid_vec, valid_vec, perturbed(valid_vec, {"origin": vectors(3), "vector": vectors(3), "label": st.one_of(st.text(), junk),
                                "scale": scalars, "color": vectors(4)}, unknown=("colour", "size")))
    axes = perturbed(st.fixed_dictionaries({"body": st.sampled_from(["x/y", "x_y"])},
                                           optional={"scale": st.floats(0.01, 2)}),
                     {"body": st.one_of(st.just("nobody"), junk), "scale": scalars}, unknown=("length",))
    valid = st.fixed_dictionaries({}, optional={"axes": st.lists(axes, max_size=2, unique_by=lambda a: repr(a.get("body"))),
                                                "vectors": st.lists(vec, max_size=3)})
    return st.one_of(st.none(), scalars, perturbed(valid, {"axes": scalars, "vectors": scalars}, unknown=("arrows",)),
                     valid, valid)


def _accepted_overlay_ok(ov) -> None:
    for v in ov["vectors"]:
        end = v["origin"] + v["scale"] * v["vector"]
        assert np.all(np.abs(v["origin"]) <= VW.FLOAT32_MAX) and np.all(np.abs(end) <= VW.FLOAT32_MAX)
        assert np.all((v["color"] >= 0) & (v["color"] <= 1)) and math.isfinite(v["scale"]) and v["scale"] > 0


@FUZZ
@given(payload=overlay_payloads())
def test_fuzz_viewer_payloads(payload):
    before = repr(payload)
    try:
        ov = _quiet(VW.validate_overlays, payload, ["x/y", "x_y"])
    except OK:
        event("payload rejected")
        assert repr(payload) == before
        return
    event(f"payload accepted ({len(ov['vectors'])} vectors)")
    assert repr(payload) == before, "validation mutated its input"
    _accepted_overlay_ok(ov)


@pytest.fixture(scope="module")
def live_viewer():
    if not have("viewer"):
        pytest.skip("viewer extra not installed (pip install 'lavendersim[viewer]')")
    s = lv.Scene()
    s.add_body(lv.Body.box("x/y", 1.0, (0.2, 0.2, 0.2)))
    s.add_body(lv.Body.box("x_y", 1.0, (0.2, 0.2, 0.2), p_w=(1, 0, 0)))
    sim = lv.Sim(s, backend="numpy")
    with VW.Viewer(port=0) as v:
        yield v, sim


@settings(FUZZ, max_examples=60)
@given(payload=overlay_payloads())
def test_fuzz_live_viewer_frames(live_viewer, payload):
    """A payload is either rejected (nothing published) or drawn: never a frame that fails later."""
    v, sim = live_viewer
    published = v.stats()["published"]
    try:
        n = _quiet(v.publish_frame, sim, payload)
    except OK:
        event("frame rejected")
        assert v.stats()["published"] == published
        return
    event("frame published")
    assert v.wait_applied(n, 60.0)       # raises ViewerError if the frame could not be drawn
    assert v.stats()["failed"] == 0 and v.last_error is None


# ---------------------------------------------------------------- a built Sim: mutation, threads, pickling, fork ------
# (issue 28) Nothing reaches the stepper unvalidated, no update is lost to a second thread, a pickled Sim steps on bit for
# bit, a fork while another thread runs never hangs. Each example builds Sims and steps them: few examples per property.
FUZZ_SIM = settings(FUZZ, max_examples=40)
FUZZ_THREADS = settings(FUZZ, max_examples=25)
FUZZ_FORK = settings(FUZZ, max_examples=12)
SETTERS = ("steps", "rhs_evals")        # the validated setters of a built Sim; every other public name is refused


def _steps(backend: str, n: int) -> int:
    """n steps on the C backend, a sixth of them on NumPy (its Python step path: ~5 ms per step of this scene)."""
    return n if backend == "c" else n // 6


def _built(backend: str, integrator: str = "rk4", wheels: bool = True):
    """A two-body Sim (a tumbling satellite with an applied torque, a cube with three wheels) and the torque effect."""
    s = lv.Scene()
    s.add_body(lv.Body("sat", 12.0, [[0.2, 0.004, -0.002], [0.004, 0.25, 0.003], [-0.002, 0.003, 0.08]],
                       omega_b=[0.3, -0.2, 0.5]))
    s.add_body(lv.Body.box("cube", 1.0, (0.2, 0.2, 0.2), omega_b=[0.1, 0.2, -0.3]))
    if wheels:
        s.add_effect("reaction_wheels", body="cube", J=[1e-4] * 3, torque_limit=0.1, speed_limit=100.0)
    push = s.add_effect("applied_torque", body="sat", torque_w=[0.0, 0.0, 1e-3])
    return lv.Sim(s, dt=1e-3, integrator=integrator, backend=backend), push


def _bits_of(sim: lv.Sim) -> tuple:
    """Everything a step can change, as bytes (== is bit for bit, NaN and -0.0 included)."""
    return (sim.x.tobytes(), sim.Omega.tobytes(), sim.wheel_torques_applied.tobytes(), sim.steps, sim.rhs_evals,
            np.float64(sim.t).tobytes())


def _names_of_a_sim() -> list[str]:
    sim, _ = _built("numpy")
    return sorted(n for n in dir(sim) if not n.startswith("_"))


SIM_NAMES = _names_of_a_sim()
values = st.one_of(scalars, vectors(3), st.integers(0, 40), st.just(None), st.just("same"),
                  st.just(lv.Body.box("sat", 5.0, (1.0, 1.0, 1.0))))     # a valid body of the same name, other mass


@FUZZ_SIM
@given(name=st.one_of(st.sampled_from(SIM_NAMES), st.sampled_from(["dT", "omega", "state_", "wheels", "brand_new"])),
       value=values, backend=st.sampled_from(BACKENDS), before=st.integers(0, 30), after=st.integers(1, 40),
       inplace=st.booleans())
def test_fuzz_mutation_after_construction(name, value, backend, before, after, inplace):
    """Assigning any public name of a built Sim raises ImmutableSimError naming ``sim.<name>`` or is a validated setter
    (then it is a LavenderInputError naming the setter, or it is accepted and means the same on a reference Sim); an
    in-place change of what a public attribute returns (an array, a dict, a list) is refused or changes nothing the
    Sim steps or pickles. Either way stepping on is bit for bit what a Sim that saw only the accepted setter does, and
    a pickled copy steps alike."""
    from lavendersim.sim import ImmutableSimError

    sim, _ = _built(backend)
    ref, _ = _built(backend)
    before, after = _steps(backend, before), max(1, _steps(backend, after))
    sim.run(before)
    ref.run(before)
    accepted = False
    if inplace and name in SIM_NAMES and not callable(getattr(sim, name)):
        target = getattr(sim, name)
        event(f"in place: {type(target).__name__}")
        try:
            if isinstance(target, np.ndarray):
                target.flat[0] = 123.0
            elif isinstance(target, dict):
                target[next(iter(target))] = value
            elif isinstance(target, list):
                target.append(value)
            elif isinstance(target, tuple):
                return
            else:
                return
        except (ValueError, TypeError, AttributeError) as exc:     # read-only arrays, mappings, tuples
            event(f"in place refused: {type(exc).__name__}")
    else:
        v = getattr(sim, name, None) if isinstance(value, str) and value == "same" else value
        try:
            setattr(sim, name, v)
            accepted = True
        except ImmutableSimError as exc:
            assert exc.field == f"sim.{name}"
            event("assignment: ImmutableSimError")
        except LavenderInputError as exc:
            assert name in SETTERS and exc.field == name, f"{name}: {exc}"
            event("assignment: setter refused")
        if accepted:
            assert name in SETTERS, f"sim.{name} = {v!r} was accepted: neither refused nor a validated setter"
            setattr(ref, name, v)
            event("assignment: setter accepted")
    assert _bits_of(sim) == _bits_of(ref)
    copy_ = pickle.loads(pickle.dumps(sim))
    for s in (sim, ref, copy_):
        try:
            _quiet(s.run, after)
        except DivergenceError:
            pass
    assert _bits_of(sim) == _bits_of(ref) == _bits_of(copy_)


OPS = st.one_of(
    st.tuples(st.just("set_state"), st.fixed_dictionaries({}, optional={
        "omega_b": st.lists(st.floats(-1, 1), min_size=3, max_size=3),
        "q": st.sampled_from([(0.0, 0.0, 0.0, 1.0), (0.1, 0.2, 0.3, 0.9), (0.0, 0.0, math.sin(0.3), math.cos(0.3))])})),
    st.tuples(st.just("set_wheel_command"), st.lists(st.floats(-0.1, 0.1), min_size=3, max_size=3)),
    st.tuples(st.just("set_effect_params"), st.lists(st.floats(-1e-2, 1e-2), min_size=3, max_size=3)))


def _apply(sim: lv.Sim, push, op) -> None:
    kind, arg = op
    if kind == "set_state":
        sim.set_state("sat", **arg)
    elif kind == "set_wheel_command":
        sim.set_wheel_command("cube", arg)
    else:
        sim.set_effect_params(push, torque_w=arg)


def _landings(bounds: list[tuple[int, int]], boundaries: list[int], start: int = 0) -> list[tuple[int, ...]]:
    """Every non-decreasing choice of a run boundary per operation within its observed [before, after] step counts."""
    if not bounds:
        return [()]
    lo, hi = bounds[0]
    return [(k, *rest) for k in boundaries if max(lo, start) <= k <= hi for rest in _landings(bounds[1:], boundaries, k)]


@FUZZ_THREADS
@given(ops=st.lists(OPS, min_size=1, max_size=3), backend=st.sampled_from(BACKENDS),
       delays=st.lists(st.sampled_from([0.0, 0.0005, 0.002]), min_size=3, max_size=3))
def test_fuzz_threads_never_lose_an_update(ops, backend, delays):
    """set_state, set_wheel_command and set_effect_params from a second thread while a run goes on land between two
    runs and are never lost: the final state is, bit for bit, a serial replay with each operation at a run boundary
    (within the step counts the second thread saw before and after it)."""
    import threading
    import time

    m, calls = (400, 6) if backend == "c" else (3, 4)
    sim, push = _built(backend)
    boundaries = [m * i for i in range(calls + 1)]
    bounds, errors = [], []
    started = threading.Event()

    def runner():
        try:
            started.set()
            for _ in range(calls):
                sim.run(m)
        except BaseException as exc:   # recorded: the test fails naming it
            errors.append(exc)

    t = threading.Thread(target=runner)
    t.start()
    started.wait(30)
    for op, delay in zip(ops, delays):
        time.sleep(delay)
        lo = sim.steps
        _apply(sim, push, op)
        bounds.append((lo, sim.steps))
    t.join(120)
    assert not t.is_alive() and not errors, errors
    final = _bits_of(sim)
    for landing in _landings(bounds, boundaries):
        ref, ref_push = _built(backend)
        done = 0
        for op, k in zip(ops, landing):
            ref.run(k - done)
            done = k
            _apply(ref, ref_push, op)
        ref.run(m * calls - done)
        if _bits_of(ref) == final:
            event(f"landed at {landing}")
            return
    pytest.fail(f"no serial replay gives the final state (ops {[o[0] for o in ops]}, step bounds {bounds}): a lost update")


@FUZZ_SIM
@given(backend=st.sampled_from(BACKENDS), integrator=st.sampled_from(["rk4", "dopri5", "implicit_gyro", "euler",
                                                                     "semi_implicit_euler", "splitting"]),
       before=st.integers(0, 60), after=st.integers(1, 60), ops=st.lists(OPS, max_size=2),
       how=st.sampled_from(["pickle", "deepcopy"]))
def test_fuzz_pickling_at_a_random_step(backend, integrator, before, after, ops, how):
    """A pickle (or deepcopy) round trip at any step, after any held command or effect change, steps on bit for bit."""
    import copy

    try:
        sim, push = _built(backend, integrator, wheels=integrator not in ("implicit_gyro",))
    except LavenderInputError:
        event(f"{integrator} refuses the scene")
        return
    for op in ops:
        if op[0] == "set_wheel_command" and integrator == "implicit_gyro":
            continue
        _apply(sim, push, op)
    before, after = _steps(backend, before), max(1, _steps(backend, after))
    try:
        _quiet(sim.run, before)
    except DivergenceError:
        return
    twin = pickle.loads(pickle.dumps(sim)) if how == "pickle" else copy.deepcopy(sim)
    assert twin is not sim and _bits_of(twin) == _bits_of(sim)
    for s in (sim, twin):
        try:
            _quiet(s.run, after)
        except DivergenceError as exc:
            event(f"diverged: {exc.cause[:30]}")
    assert _bits_of(twin) == _bits_of(sim)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
@FUZZ_FORK
@given(backend=st.sampled_from(BACKENDS), delay=st.sampled_from([0.0, 0.0002, 0.001, 0.005]),
       child_steps=st.integers(1, 20))
def test_fuzz_fork_while_another_thread_runs(backend, delay, child_steps):
    """os.fork while a second thread runs the Sim: the child steps the Sim on (its lock is fresh, whoever held it in
    the parent) and exits 0; the parent's run finishes too."""
    import threading
    import time

    sim, _ = _built(backend)
    stop, errors = threading.Event(), []

    def runner():
        try:
            while not stop.is_set():
                sim.run(200 if backend == "c" else 3)
        except BaseException as exc:   # recorded: the test fails naming it
            errors.append(exc)

    t = threading.Thread(target=runner)
    t.start()
    time.sleep(delay)
    pid = os.fork()
    if pid == 0:          # the child: only this thread exists; never back into pytest/hypothesis
        code = 1
        try:
            n0 = sim.steps
            sim.run(child_steps)
            code = 0 if sim.steps == n0 + child_steps and np.all(np.isfinite(sim.x)) else 3
        finally:
            os._exit(code)
    stop.set()
    t.join(120)
    deadline = time.monotonic() + 120
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            pytest.fail("the forked child hung")
        time.sleep(0.01)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    assert not t.is_alive() and not errors, errors
