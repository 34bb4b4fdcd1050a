"""ReactionWheelCube-v0's vector env checked the way gymnasium's check_env checks a single env (gymnasium has
no checker for vector envs): batched spaces, reset/step return types, seed and step determinism, returned
arrays not reused between calls; and the C backend's threads (the suite needs the C extension): the cubes of one call shared over two threads
give bitwise the results of one thread (the vector env's physics), divergence reported alike."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import missing
from lavendersim.generated import layout as LY

pytestmark = pytest.mark.needs("gym")
if missing("gym") is None:
    import gymnasium as gym
    from gymnasium.utils.env_checker import data_equivalence

    from lavendersim.envs.vector import ReactionWheelCubeVectorEnv

N = 6


def _vec(n=N, **kw):
    return gym.make_vec("lavendersim:ReactionWheelCube-v0", num_envs=n, vectorization_mode="vector_entry_point", **kw)


def test_spaces_and_return_types():
    ve = _vec()
    one = gym.make("lavendersim:ReactionWheelCube-v0").unwrapped
    assert isinstance(ve, ReactionWheelCubeVectorEnv) and ve.num_envs == N
    assert ve.single_observation_space == one.observation_space and ve.single_action_space == one.action_space
    assert ve.observation_space.shape == (N, 10) and ve.observation_space.dtype == np.float32
    assert ve.action_space.shape == (N, 3) and ve.action_space.dtype == np.float32
    obs, info = ve.reset(seed=3)
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and obs.shape == (N, 10) and isinstance(info, dict)
    assert obs in ve.observation_space
    ve.action_space.seed(1)
    for _ in range(30):
        obs, rew, term, trunc, info = ve.step(ve.action_space.sample())
        assert obs.dtype == np.float32 and obs.shape == (N, 10) and obs in ve.observation_space
        assert rew.dtype == np.float64 and rew.shape == (N,) and np.all(np.isfinite(rew)) and np.all(rew <= 0)
        assert term.dtype == bool and trunc.dtype == bool and term.shape == trunc.shape == (N,)
        assert isinstance(info, dict) and info["angle_error_deg"].shape == (N,)
        assert all(f"_{k}" in info for k in info if not k.startswith("_"))   # gymnasium's `_key` masks
        assert "_diverged" not in info and info["_angle_error_deg"].dtype == bool and info["_angle_error_deg"].all()
        assert info["torque_applied"].shape == (N, 3)
    ve.close()


def test_reset_info_is_the_single_envs_per_cube_with_masks():
    """reset() returned an empty info; now the single env's reset measures (its clock `t` aside) per cube, the
    `_key` masks marking the cubes that were reset (gymnasium's convention, as SyncVectorEnv's reset gives)."""
    ve = _vec(3, task="corner")
    obs, info = ve.reset(seed=5)
    assert set(info) == {"angle_error_deg", "torque_applied", "tilt_deg", "_angle_error_deg", "_torque_applied",
                         "_tilt_deg"}
    for i in range(3):
        o1, i1 = gym.make("lavendersim:ReactionWheelCube-v0", task="corner").unwrapped.reset(seed=5 + i)
        np.testing.assert_array_equal(obs[i], o1)
        for key in ("angle_error_deg", "tilt_deg"):     # the single env computes them one cube at a time
            assert info[key][i] == pytest.approx(i1[key], rel=1e-12, abs=1e-12) and info[f"_{key}"][i], key
        np.testing.assert_array_equal(info["torque_applied"][i], i1["torque_applied"])
    ve.step(np.ones((3, 3), np.float32))
    obs, info = ve.reset(options={"reset_mask": np.array([False, True, False])})
    assert info["_tilt_deg"].tolist() == [False, True, False] == info["_angle_error_deg"].tolist()
    ve.close()


def test_seed_and_step_determinism():
    """check_reset_seed_determinism and check_step_determinism, batched: two envs seeded alike and given the same
    actions return equal data, exactly."""
    a, b = _vec(), _vec()
    ra, rb = a.reset(seed=123), b.reset(seed=123)
    assert data_equivalence(ra, rb, exact=True)
    assert data_equivalence(a.reset(seed=123), ra, exact=True)
    rng = np.random.default_rng(5)
    for _ in range(25):
        act = rng.uniform(-1, 1, (N, 3)).astype(np.float32)
        assert data_equivalence(a.step(act), b.step(act), exact=True)


def test_returned_data_not_reused():
    """check_returned_data_not_reused, batched: arrays returned by one call are not overwritten by the next."""
    ve = _vec()
    o0, _ = ve.reset(seed=0)
    keep0 = o0.copy()
    out1 = ve.step(np.full((N, 3), 0.5, np.float32))
    keep1 = [x.copy() for x in out1[:4]]
    out2 = ve.step(np.full((N, 3), -0.5, np.float32))
    assert np.array_equal(o0, keep0) and not np.shares_memory(o0, out1[0])
    for x, k, y in zip(out1[:4], keep1, out2[:4]):
        assert np.array_equal(x, k) and not np.shares_memory(x, y)
    assert not np.array_equal(out1[0], out2[0])


def _c_cubes(n):
    """The arrays a vector env of n cubes hands to the C backend, with spread initial rates and commands."""
    ve = _vec(n)
    ve.reset(seed=4)
    sim = ve.unwrapped.sim
    rng = np.random.default_rng(9)
    m = sim._models
    x = sim._x.copy()
    x[:, 10:13] = rng.uniform(-3, 3, (n, 3))
    cmd, Om = np.zeros((n, LY.WHEELS_MAX)), np.zeros((n, LY.WHEELS_MAX))   # the cubes' three wheels: the first slots
    cmd[:, :3] = rng.uniform(-0.25, 0.25, (n, 3))          # beyond the torque limit too: saturated
    Om[:, :3] = rng.uniform(-50, 50, (n, 3))
    return x, sim.params, sim._step_effects, m.rows, Om, cmd


@pytest.mark.parametrize("integrator", [0, 1, 2])         # euler, semi_implicit_euler, rk4
def test_two_threads_are_one_thread_bitwise(integrator):
    from lavendersim.backends import c_backend as C

    n, steps = 300, 40          # 12 000 body-steps: the cubes are split over the threads
    x0, params, effects, rows, Om0, cmd = _c_cubes(n)
    out = {}
    try:
        for threads in (1, 2):
            assert C.threads(threads) in (1, threads)
            x, Om, applied = x0.copy(), Om0.copy(), np.zeros((n, LY.WHEELS_MAX))
            status = C._c.simulate(x, params, effects, integrator, 1, 1e-3, steps, rows, Om, cmd, applied,
                                   None, None, 0.0, 0.0, None)
            out[threads] = (status, x, Om, applied)
    finally:
        C.threads(1)
    assert out[1][0][0] == 0 and out[1][0] == out[2][0]
    for a, b in zip(out[1][1:], out[2][1:]):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(out[1][1], x0)       # it moved


def test_divergence_with_two_threads_is_reported_as_with_one():
    """Two cubes blow up (one in each thread's share; the later body first): the same step and body, and the
    failing body left at its last finite state, with one thread or two."""
    from lavendersim.backends import c_backend as C

    n, steps = 300, 40
    x0, params, effects, rows, Om0, cmd = _c_cubes(n)
    x0[40, 10:13] = [1e153, 0.0, 0.0]        # |omega|^2 overflows after a few steps
    x0[250, 10:13] = [1e154, 0.0, 0.0]       # sooner: the reported one
    res = {}
    try:
        for threads in (1, 2):
            C.threads(threads)
            x, Om, applied = x0.copy(), Om0.copy(), np.zeros((n, LY.WHEELS_MAX))
            status, step, body = C._c.simulate(x, params, effects, 2, 1, 1e-3, steps, rows, Om, cmd, applied,
                                               None, None, 0.0, 0.0, None)
            res[threads] = (status, step, body, x[body].copy(), Om[body].copy())
    finally:
        C.threads(1)
    assert res[1][0] == 1 and res[1][2] in (40, 250)
    assert res[1][:3] == res[2][:3]
    np.testing.assert_array_equal(res[1][3], res[2][3])
    np.testing.assert_array_equal(res[1][4], res[2][4])


def test_vector_env_with_two_threads_equals_one_thread():
    from lavendersim.backends import c_backend as C

    n = 128                     # 1 280 body-steps per env step: shared over two threads
    outs = {}
    try:
        for threads in (1, 2):
            C.threads(threads)
            ve = _vec(n)
            ve.reset(seed=8)
            rng = np.random.default_rng(2)
            outs[threads] = [ve.step(rng.uniform(-1, 1, (n, 3)).astype(np.float32))[:4] for _ in range(15)]
    finally:
        C.threads(1)
    assert data_equivalence(outs[1], outs[2], exact=True)


# ------------------------------------------------------------------ the step's C fast path (issue 12)

def _sim_run_path(ve):
    """ve's Sim with the C fast path off: every run takes Sim._advance (the Python path), every written state is
    checked there."""
    ve.sim._fast_n = 0
    object.__setattr__(ve.sim, "check_written", lambda: None)   # (a built Sim takes no public assignment)
    return ve


def _count_python_path(sim):
    calls, real = [], sim._advance
    sim._advance = lambda n: (calls.append(n), real(n))[1]
    return calls


@pytest.mark.parametrize("task,n", [("center", 5), ("corner", 5), ("center", 1030)])
def test_fast_path_equals_sim_run_path(task, n):
    """Each step's run inside C (Sim.fast_chunks: Stepper.advance, also beyond FAST_STEP_WORK at n = 1030) gives
    bitwise the results of the Python path, through autoresets (the reset cubes' states checked at once, so the
    Python path is never taken) and actions beyond ±1, float32, float64 and lists."""
    kw = dict(task=task, max_episode_steps=9)
    fast, ref = _vec(n, **kw), _sim_run_path(_vec(n, **kw))
    assert fast.sim._fast is not None and fast.sim._fast_n >= fast.substeps
    calls = _count_python_path(fast.sim)
    assert data_equivalence(fast.reset(seed=3), ref.reset(seed=3), exact=True)
    rng = np.random.default_rng(1)
    ends = 0
    for k in range(30):
        a = rng.uniform(-1.5, 1.5, (n, 3))
        a = a.astype(np.float32) if k % 3 == 0 else a.tolist() if k % 3 == 1 else a
        out_f, out_r = fast.step(a), ref.step(a)
        assert data_equivalence(out_f, out_r, exact=True)
        ends += int(np.sum(out_f[3]))
    assert ends >= n and calls == []     # resets every 9 steps, none of them sent a run to the Python path


def test_fast_path_divergence_is_caught_and_reported_as_before():
    """A cube pushed beyond rk4's validity bound inside a step's C run: the Stepper refuses the chunk (nothing
    changed), Sim.run's Python path raises, the sub-env terminates with -1e3 and info["diverged"] exactly as on the
    Python path; the others advance alike."""
    envs = [_vec(3, damping=0.0), _sim_run_path(_vec(3, damping=0.0))]
    outs = []
    for ve in envs:
        ve.reset(seed=1)
        sim = ve.unwrapped.sim
        w_lim = float(sim._bound[0] / sim._wdt_scale[1])
        ve.unwrapped._place(1, sim.q[1].copy(), np.array([w_lim * 0.99995, 0.0, 0.0]), np.zeros(3))
        sim.check_written()                       # (the reference's is off: its Python path checks it)
        a = np.zeros((3, 3), np.float32)
        a[1] = -1.0                                # spins the cube up beyond the bound within the step
        outs.append((ve.step(a), ve.step(a)))
    assert envs[0].sim._fast.is_checked()
    (o, r, t, u, info), second = outs[0]
    assert t.tolist() == [False, True, False] and r[1] == -1e3 and info["diverged"].tolist() == [False, True, False]
    assert "validity bound" in info["diverged_message"][1]
    # gymnasium's `_key` masks: the divergence is about cube 1 only; the measures are about every cube
    assert info["_diverged"].tolist() == [False, True, False] and info["_diverged_message"].tolist() == [False, True, False]
    assert info["_angle_error_deg"].tolist() == [True, True, True] and info["_torque_applied"].all()
    np.testing.assert_equal(outs[0], outs[1])       # bitwise, the NaN angle of the diverged one at the same place
    assert second[1][1] == 0.0 and not second[2][1]          # autoreset by the next step


def test_actions_saturated_and_checked():
    """Actions beyond ±1 are saturated (a float32, float64 or list input alike, the caller's array untouched); a
    non-finite action or a wrong shape raises LavenderInputError naming actions and changes nothing."""
    from lavendersim.validate import LavenderInputError

    n = 4
    envs = [_vec(n) for _ in range(4)]
    for ve in envs:
        ve.reset(seed=7)
    a = np.array([[3.0, -7.0, 0.5], [-1.0, 1.0, 1.0000001], [np.finfo(np.float64).max] * 3, [-2.0, 0.0, 0.25]])
    keep = a.copy()
    outs = [envs[0].step(a), envs[1].step(np.clip(a, -1, 1)), envs[2].step(a.tolist()),
            envs[3].step(np.clip(a, -1, 1).astype(np.float32))]
    assert np.array_equal(a, keep)
    for out in outs[1:3]:
        assert data_equivalence(outs[0], out, exact=True)
    assert np.array_equal(outs[0][0], outs[3][0]) or not np.array_equal(np.clip(a, -1, 1),
                                                                         np.clip(a, -1, 1).astype(np.float32))
    tl = envs[0].torque_limit
    np.testing.assert_array_equal(envs[0].sim._models.command[:, :3], np.clip(a, -1, 1) * tl)
    assert not envs[0].sim._models.command[:, 3:].any()     # the unused wheel slots stay 0
    x = envs[0].sim.x.copy()
    for bad in (np.where(np.eye(n, 3) > 0, np.nan, 0.0), np.full((n, 3), np.inf, np.float32), np.zeros((n, 2)),
                [[0.0, 0.0, float("-inf")]] * n):
        with pytest.raises(LavenderInputError, match="actions"):
            envs[0].step(bad)
    assert np.array_equal(envs[0].sim.x, x)
