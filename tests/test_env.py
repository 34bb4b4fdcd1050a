"""ReactionWheelCube-v0: registration, gymnasium's env checker (warnings as errors), spaces,
seeding, reward/termination, rendering without a display, bad actions, both backends."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import missing

import lavendersim
from lavendersim.validate import LavenderInputError

# The gym extra: every test is skipped without gymnasium, failed under CI=true (tests/conftest.py).
pytestmark = pytest.mark.needs("gym")
if missing("gym") is None:
    import gymnasium as gym

    from lavendersim.envs.reaction_wheel_cube import ReactionWheelCubeEnv

BACKENDS = ("c", "numpy")


def test_registered_on_import():
    assert "ReactionWheelCube-v0" in gym.registry
    lavendersim.envs.register()  # idempotent
    env = gym.make("lavendersim:ReactionWheelCube-v0")
    assert isinstance(env.unwrapped, ReactionWheelCubeEnv)
    assert env.spec.max_episode_steps == 1000
    env.close()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("task", ["center", "corner"])
@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
def test_check_env_warnings_as_errors(backend, task, render_mode):
    from gymnasium.utils.env_checker import check_env

    env = gym.make("lavendersim:ReactionWheelCube-v0", backend=backend, task=task, render_mode=render_mode)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


def test_spaces_and_observation():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    assert env.action_space == gym.spaces.Box(-1, 1, (3,), np.float32)
    assert env.observation_space.shape == (10,) and env.observation_space.dtype == np.float32
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and obs in env.observation_space
    st = env.sim.state("cube")
    assert np.allclose(obs[0:4], st.q, atol=1e-7) and np.all(obs[4:] == 0)
    assert 0 <= info["angle_error_deg"] <= 20.0


def test_seeding_reproduces_episodes():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    a = np.array([0.3, -0.5, 0.9], np.float32)
    o1, _ = env.reset(seed=42)
    s1 = [env.step(a)[0] for _ in range(5)]
    o2, _ = env.reset(seed=42)
    s2 = [env.step(a)[0] for _ in range(5)]
    o3, _ = env.reset(seed=43)
    assert np.array_equal(o1, o2) and all(np.array_equal(x, y) for x, y in zip(s1, s2))
    assert not np.array_equal(o1, o3)


def test_positive_x_action_spins_wheel_positive_cube_negative():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=0, options={"q": [0, 0, 0, 1]})
    for _ in range(10):
        obs, *_ = env.step(np.array([0.5, 0, 0], np.float32))
        assert obs[7] > 0 and obs[4] < 0


def test_action_is_scaled_and_saturated():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.5, -1.0, 0.0], np.float32))
    # 0.1 is below the line's available torque; −0.2 is the stall torque, 0.2 (1 − |Ω|/400) after the first substeps
    assert info["torque_applied"][0] == pytest.approx(0.1) and -0.2 < info["torque_applied"][1] < -0.19
    Om = env.sim.wheel_rates("cube")
    _, _, _, _, info = env.step(np.array([7.0, -3.0, 0.25]))  # outside the box: saturated
    # clipped to the 0.2 N·m stall torque, then the motor's torque–speed line (issue 13): < 0.2 once spinning
    from lavendersim.kernels import K

    cmd = np.array([1.4, -0.6, 0.05])
    hi = np.abs(K.wheel_motor(cmd, Om, 0.2, 400.0, 0.0))                               # at the step's start
    lo = np.abs(K.wheel_motor(cmd, env.sim.wheel_rates("cube"), 0.2, 400.0, 0.0))      # at its end
    got = np.abs(info["torque_applied"])   # the last 1 ms substep's torque
    assert np.all(lo - 1e-12 <= got) and np.all(got <= hi + 1e-12) and 0.19 < got[0] < 0.2 and got[2] == 0.05


def test_wheel_speed_limit_reaches_the_env():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=0, options={"Omega": [400.0, 0, 0]})
    _, _, _, _, info = env.step(np.array([1.0, 0, 0], np.float32))
    assert info["torque_applied"][0] == 0.0


@pytest.mark.parametrize("bad", [np.zeros(2), np.zeros((3, 1)), np.array([0, np.nan, 0]), np.array([np.inf, 0, 0]), "abc", None])
def test_bad_actions_raise(bad):
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(LavenderInputError) as e:
        env.step(bad)
    assert e.value.field == "action"


def test_bad_constructor_and_reset_options():
    with pytest.raises(LavenderInputError) as e:
        ReactionWheelCubeEnv(backend="gpu")
    assert e.value.field == "backend"
    with pytest.raises(LavenderInputError) as e:
        ReactionWheelCubeEnv(render_mode="human")
    assert e.value.field == "render_mode"
    with pytest.raises(LavenderInputError) as e:
        ReactionWheelCubeEnv(task="edge")
    assert e.value.field == "task"
    env = ReactionWheelCubeEnv()
    with pytest.raises(LavenderInputError) as e:
        env.reset(options={"spin": 1})
    assert e.value.field == "options.spin"
    with pytest.raises(LavenderInputError):
        env.reset(options={"q": [0, 0, 0, 0]})


def test_reward_is_zero_at_target_and_negative_elsewhere():
    env = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    env.reset(seed=0, options={"q": [0, 0, 0, 1]})
    _, r, *_ = env.step(np.zeros(3, np.float32))
    assert r == 0.0
    env.reset(seed=0, options={"q": [np.sin(0.05), 0, 0, np.cos(0.05)]})
    _, r, *_ = env.step(np.zeros(3, np.float32))
    assert r == pytest.approx(-(0.1 ** 2), rel=1e-3)


def test_corner_task_terminates_when_it_falls_and_truncates_at_max_steps():
    env = gym.make("lavendersim:ReactionWheelCube-v0", task="corner", max_tilt_deg=10.0)
    env.reset(seed=0)
    term, n = False, 0
    while not term and n < 500:
        _, _, term, trunc, info = env.step(np.zeros(3, np.float32))
        n += 1
    assert term and info["tilt_deg"] > 10.0 and not trunc
    env = gym.make("lavendersim:ReactionWheelCube-v0", max_episode_steps=3)
    env.reset(seed=0)
    out = [env.step(np.zeros(3, np.float32)) for _ in range(3)]
    assert [o[3] for o in out] == [False, False, True]


def test_render_rgb_array_without_display():
    env = gym.make("lavendersim:ReactionWheelCube-v0", render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and img.std() > 0
    env2 = gym.make("lavendersim:ReactionWheelCube-v0")
    env2.reset(seed=0)
    assert env2.render() is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_backends_agree(backend):
    envs = [gym.make("lavendersim:ReactionWheelCube-v0", backend=b).unwrapped for b in ("c", backend)]
    outs = []
    for env in envs:
        env.reset(seed=7)
        outs.append([env.step(np.array([0.2, -0.7, 0.4], np.float32))[0] for _ in range(20)])
    assert np.max(np.abs(np.array(outs[0]) - np.array(outs[1]))) < 1e-5


# ------------------------------------------------------------------ the vector env (issue 12)

def _vec(n, mode, **kw):
    return gym.make_vec("lavendersim:ReactionWheelCube-v0", num_envs=n, vectorization_mode=mode, **kw)


@pytest.mark.parametrize("task", ["center", "corner"])
def test_vector_env_equals_n_single_envs_with_autoreset(task):
    """gymnasium's SyncVectorEnv over N single envs (next-step autoreset, seeds s + i) is the reference:
    observations, terminations and truncations equal bitwise, rewards to rounding, through resets."""
    from lavendersim.envs.vector import ReactionWheelCubeVectorEnv

    n = 5
    kw = dict(task=task, max_episode_steps=40)
    ve, se = _vec(n, "vector_entry_point", **kw), _vec(n, "sync", **kw)
    assert isinstance(ve, ReactionWheelCubeVectorEnv) and ve.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    assert se.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    o1, _ = ve.reset(seed=11)
    o2, _ = se.reset(seed=11)
    assert np.array_equal(o1, o2) and o1.dtype == np.float32 and o1 in ve.observation_space
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(120):
        a = rng.uniform(-1.2, 1.2, (n, 3)).astype(np.float32)     # beyond ±1 too: saturated alike
        r1, r2 = ve.step(a), se.step(a)
        assert np.array_equal(r1[0], r2[0]) and r1[0] in ve.observation_space
        assert np.array_equal(r1[2], r2[2]) and np.array_equal(r1[3], r2[3])
        np.testing.assert_allclose(r1[1], r2[1], rtol=1e-12, atol=1e-12)
        ends += int(np.sum(r1[2] | r1[3]))
    assert ends >= n          # every sub-env truncated at least once (40 steps) and was reset by the next step
    ve.close()
    se.close()


def test_vector_env_seeding_is_per_env_and_reproducible():
    ve = _vec(3, "vector_entry_point")
    a, _ = ve.reset(seed=5)
    b, _ = ve.reset(seed=5)
    c, _ = ve.reset(seed=[5, 6, 7])
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert not np.array_equal(a[0], a[1])                     # each sub-env its own generator
    single = gym.make("lavendersim:ReactionWheelCube-v0")
    o, _ = single.reset(seed=6)
    assert np.array_equal(a[1], o)
    d, _ = ve.reset(seed=[None, 6, None])                      # only sub-env 1 re-seeded
    assert np.array_equal(d[1], a[1])
    mask = np.array([False, True, False])
    e, _ = ve.reset(seed=6, options={"reset_mask": mask})     # reset sub-env 1 only (seed 6 + 1)
    assert np.array_equal(e[0], d[0]) and np.array_equal(e[2], d[2])
    for bad, field in (({"seed": -1}, "seed"), ({"seed": [1, 2]}, "seed"), ({"options": {"q": 1}}, "options.q"),
                       ({"options": {"reset_mask": [1, 0, 1]}}, "options.reset_mask")):
        with pytest.raises(LavenderInputError, match=field):
            ve.reset(**bad)
    with pytest.raises(LavenderInputError, match="actions"):
        ve.step(np.full((3, 3), np.nan))
    with pytest.raises(LavenderInputError, match="actions"):
        ve.step(np.zeros((2, 3)))
    with pytest.raises(LavenderInputError, match="num_envs"):
        _vec(0, "vector_entry_point")
    with pytest.raises(LavenderInputError, match="render_mode"):
        _vec(2, "vector_entry_point", render_mode="rgb_array")


def test_vector_env_divergence_ends_only_that_sub_env():
    """A DivergenceError of one cube (here injected by a Sim.run that raises once for body 1, as a real one
    does: the Sim restored) terminates that sub-env with reward -1e3 and its pre-step observation; the
    others advance exactly as without it; the next step resets it."""
    from lavendersim.errors import DivergenceError

    n = 3
    ve, ref = _vec(n, "vector_entry_point"), _vec(n, "vector_entry_point")
    o0, _ = ve.reset(seed=2)
    ref.reset(seed=2)
    sim, real_run = ve.sim, ve.sim.run
    calls = []

    def run_once_diverging(k):
        calls.append(k)
        if len(calls) == 1:
            raise DivergenceError(3, 1, "injected", "cube1")
        return real_run(k)
    object.__setattr__(sim, "run", run_once_diverging)    # (a built Sim refuses public assignment)
    a = np.full((n, 3), 0.3, np.float32)
    obs, rew, term, trunc, info = ve.step(a)
    r_obs, r_rew, *_ = ref.step(a)
    assert term.tolist() == [False, True, False] and rew[1] == -1e3 and info["diverged"].tolist() == [False, True, False]
    assert "injected" in info["diverged_message"][1]
    assert np.array_equal(obs[1], o0[1])                              # its state before the step
    assert np.array_equal(obs[[0, 2]], r_obs[[0, 2]]) and np.array_equal(rew[[0, 2]], r_rew[[0, 2]])
    obs2, rew2, term2, *_ = ve.step(a)                                 # next-step autoreset of sub-env 1
    assert rew2[1] == 0.0 and not term2[1]


def test_vector_env_steps_all_cubes_in_one_sim_call():
    ve = _vec(4, "vector_entry_point")
    ve.reset(seed=0)
    sim = ve.sim
    assert len(sim.names) == 4
    calls = []
    real = sim.run
    object.__setattr__(sim, "run", lambda k: (calls.append(k), real(k))[1])    # (a built Sim refuses assignment)
    ve.step(np.zeros((4, 3), np.float32))
    assert calls == [ve.substeps]


@pytest.mark.parametrize("task", ["center", "corner"])
def test_step_fast_path_equals_sim_run_path(task):
    """env.step calls Sim.run's C fast path directly (a Stepper's advance): its results equal those of the Sim.run
    path bitwise, including a step whose rates leave the observation bounds (clipped observation, out_of_bounds)."""
    envs = [gym.make("lavendersim:ReactionWheelCube-v0", task=task).unwrapped for _ in range(2)]
    for e in envs:
        e.reset(seed=3, options={"omega_b": [0.0, 0.0, 199.0], "Omega": [0.0, 0.0, 799.8]})
    envs[1]._bind(envs[1].sim).advance = None          # the second env takes Sim.run every step
    assert envs[0]._bind(envs[0].sim).advance is not None
    seen_out = False
    for k in range(6):
        a = np.array([0.3 * (-1) ** k, -0.2, 1.0], np.float32)
        (o0, r0, t0, u0, i0), (o1, r1, t1, u1, i1) = envs[0].step(a), envs[1].step(a)
        assert o0.dtype == np.float32 and o0 in envs[0].observation_space
        assert np.array_equal(o0, o1) and r0 == r1 and (t0, u0) == (t1, u1)
        assert i0.keys() == i1.keys() and np.array_equal(i0["torque_applied"], i1["torque_applied"])
        assert all(i0[key] == i1[key] for key in i0 if key != "torque_applied")
        seen_out |= bool(i0.get("out_of_bounds"))
    assert seen_out     # the z wheel passed 800 rad/s (the cube's damping spins it up): observation clipped there
    assert o0[9] == envs[0].observation_space.high[9]
