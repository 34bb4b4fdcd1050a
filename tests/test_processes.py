"""A Sim, its envs and its errors survive processes (issue 28): every exception class of the package pickles with
its fields (found by walking the package, so a new one cannot be missed), the envs pickle and deep-copy bit for bit
(state, counters, held commands, episode step counts, random generators), and the executor reports a task that
cannot be sent and a task that diverges as what they are, on local processes and on a local Dask cluster."""
from __future__ import annotations

import copy
import importlib
import importlib.util
import inspect
import pickle
import pkgutil
import threading

import numpy as np
import pytest

import lavendersim as lv
from lavendersim import executor as X
from lavendersim.errors import DivergenceError
from lavendersim.validate import LavenderInputError

from conftest import IN_CI, have, require

# ---- every exception class of the package ------------------------------------------------------------------

# the packages walked (lavendersim.derive, .labs and .generated live in folders of their own); never their __main__
PACKAGES = ("lavendersim", "lavendersim.derive", "lavendersim.labs", "lavendersim.generated")


def _package_modules() -> list[str]:
    names = []
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        names.append(pkg)
        names += [m.name for m in pkgutil.walk_packages(mod.__path__, pkg + ".") if not m.name.endswith("__main__")]
    return sorted(set(names))


def _exception_classes() -> list[type]:
    found = {}
    for name in _package_modules():
        try:
            mod = importlib.import_module(name)
        except ImportError:     # an optional extra missing: that module's classes cannot be raised here (CI has all)
            if IN_CI:
                raise
            continue
        for obj in vars(mod).values():
            if (isinstance(obj, type) and issubclass(obj, BaseException)
                    and obj.__module__.split(".")[0] == "lavendersim"):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return [found[k] for k in sorted(found)]


def _exception_names() -> list[str]:
    """"module:qualname" of every module-level class of the packages whose bases make it an exception, read from the
    sources (ast), without importing them: collection runs in each pytest worker, and importing every module there
    (matplotlib, SymPy, python-control, ...) cost each worker ~4 s CPU. A base counts when it is a builtin exception
    or a class of the packages found so (by name); test_the_walk_finds_the_package_exceptions checks that this list
    is what importing every module finds."""
    import ast
    import builtins
    import re
    from pathlib import Path

    classes = []                 # (module, name, base names)
    for pkg in PACKAGES:
        spec = importlib.util.find_spec(pkg)
        for folder in spec.submodule_search_locations:
            for path in sorted(Path(folder).rglob("*.py")):
                rel = path.relative_to(folder).with_suffix("").parts
                if rel[-1] == "__main__" or "__pycache__" in rel:
                    continue
                module = ".".join((pkg, *rel[:-1]) + (() if rel[-1] == "__init__" else (rel[-1],)))
                text = path.read_text(encoding="utf-8")
                if not re.search(r"^class ", text, re.M):       # no module-level class (generated/'s kernels)
                    continue
                for node in ast.parse(text).body:
                    if isinstance(node, ast.ClassDef):
                        bases = [b.id if isinstance(b, ast.Name) else b.attr for b in node.bases
                                 if isinstance(b, (ast.Name, ast.Attribute))]
                        classes.append((module, node.name, bases))
    known = {n for n, v in vars(builtins).items() if isinstance(v, type) and issubclass(v, BaseException)}
    found: set[str] = set()
    while True:                  # to a fixed point: a class deriving from one found in an earlier round
        more = {f"{m}:{n}" for m, n, bases in classes if known.intersection(bases)} - found
        if not more:
            return sorted(found)
        found |= more
        known |= {k.split(":")[1] for k in more}


def pytest_generate_tests(metafunc):
    # the names are found at collection, not on import: worker processes import this module for its task functions
    if "exc_cls" in metafunc.fixturenames:
        metafunc.parametrize("exc_cls", _exception_names(), ids=lambda k: k.split(":")[1], indirect=True)


@pytest.fixture
def exc_cls(request):
    """The exception class named "module:qualname" (imported here: a module of a missing extra skips, fails in CI)."""
    module, name = request.param.split(":")
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        if IN_CI:
            raise
        pytest.skip(f"{module} does not import here ({exc})")
    cls = getattr(mod, name)
    assert isinstance(cls, type) and issubclass(cls, BaseException), request.param
    return cls

# representative values for an __init__ argument, by the words of its annotation (first match)
_SAMPLES = (("complex", 1.5 - 2j), ("bool", True), ("tuple", ("omega_b[0]", "Omega[1]")), ("int", 7), ("float", 0.25),
            ("str", "body.omega_w"), ("path", "/tmp/some/file.py"))


def _sample(param: inspect.Parameter, i: int):
    ann = param.annotation if isinstance(param.annotation, str) else getattr(param.annotation, "__name__", "")
    for word, value in _SAMPLES:
        if word in str(ann).lower():
            return f"{value}-{i}" if isinstance(value, str) else value if isinstance(value, (bool, tuple)) else value + i
    return f"value {i} of {param.name}"


def _construct(cls: type) -> BaseException:
    """An instance of cls built with representative arguments: its own __init__'s parameters (by annotation),
    or a message."""
    init = cls.__init__
    if any(init is getattr(b, "__init__", None) for b in (BaseException, Exception, ImportError, OSError)):
        return cls("a message naming field x and the rule it broke")
    args = []
    for i, p in enumerate(list(inspect.signature(init).parameters.values())[1:]):
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        args.append(_sample(p, i))
    return cls(*args)


def _fields(e: BaseException) -> dict:
    """Everything an exception carries that a receiver could read: type, message, args, attributes (incl. notes)."""
    out = {"type": type(e), "str": str(e), "args": e.args, "vars": dict(vars(e))}
    for attr in ("name", "path", "errno", "strerror", "filename"):    # ImportError's and OSError's own fields
        if hasattr(e, attr):
            out[attr] = getattr(e, attr)
    return out


def test_the_walk_finds_the_package_exceptions():
    found = _exception_classes()
    names = {c.__qualname__ for c in found}
    # what the pickling test below is parametrized with (read from the sources) is what importing every module finds
    assert {f"{c.__module__}:{c.__qualname__}" for c in found} <= set(_exception_names())
    assert len(found) == len(_exception_names()) or not IN_CI
    # a sample of what must be there (the walk works): one per module family
    for n in ("LavenderInputError", "DivergenceError", "ImmutableSimError", "ImmutableEffectError", "ImmutableBodyError",
              "MissingExtraError", "WorkerMismatchError", "UserBuildError", "CompileError", "OutputFolderError"):
        assert n in names
    assert len(found) >= 14


def test_every_exception_pickles_with_its_fields(exc_cls):
    e = _construct(exc_cls)
    e.add_note("a note added on the way")
    e.extra_attribute = ("set", 2)        # an attribute set after construction travels too
    for copy_ in (lambda v: pickle.loads(pickle.dumps(v)), copy.deepcopy, copy.copy):
        back = copy_(e)
        assert back is not e
        got, want = _fields(back), _fields(e)
        got_later, want_later = ({k: f["vars"].pop(k, None) for k in ("__notes__", "extra_attribute")} for f in (got, want))
        assert got == want                   # type, message, args, the fields __init__ set
        assert got_later == want_later       # and what was added later (a hand-written (cls, args) __reduce__ drops it)


def test_a_divergence_error_from_a_sim_pickles_with_its_fields():
    sc = lv.Scene()
    sc.add_body(lv.Body("b", 1.0, [1.0, 2.0, 3.0], omega_b=[0.0, 40.0, 0.1]))
    sim = lv.Sim(sc, dt=0.05, integrator="euler")
    with pytest.raises(DivergenceError) as ei:
        sim.run(100)
    back = pickle.loads(pickle.dumps(ei.value))
    assert _fields(back) == _fields(ei.value)
    assert (back.step, back.body, back.body_name) == (ei.value.step, 0, "b")


# ---- the envs: pickle and deepcopy, bit for bit -------------------------------------------------------------

def _bits(v):
    """A value as something == compares bit for bit (floats and arrays by their bytes, NaN and -0.0 included)."""
    if isinstance(v, dict):
        return {k: _bits(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return tuple(_bits(x) for x in v)
    if isinstance(v, (np.ndarray, np.generic, float)):
        a = np.asarray(v)
        return (a.dtype.str, a.shape, a.tobytes() if a.dtype != object else tuple(a.ravel().tolist()))
    return v


def _episodes(env, actions, vector=False) -> list:
    """Step `env` with `actions`, resetting (no seed: its generator draws the next start) where an episode ends;
    every return value, as bits."""
    out = []
    for a in actions:
        r = env.step(a)
        out.append(_bits(r))
        if not vector and (r[2] or r[3]):
            out.append(_bits(env.reset()))
        elif vector and (r[2].any() or r[3].any()):
            out.append("ended")
    return out


def _copies():
    return {"pickle": lambda e: pickle.loads(pickle.dumps(e)), "deepcopy": copy.deepcopy}


@pytest.mark.parametrize("backend", ["c", "numpy"])
@pytest.mark.parametrize("task", ["center", "corner"])
def test_an_env_pickles_and_deep_copies_bit_for_bit(backend, task):
    """A snapshot mid-episode (gymnasium.make's wrappers: the TimeLimit's step count; the env's generator, Sim, held
    command, applied torques and counters) steps on bit for bit through truncations, terminations and unseeded resets;
    the original, stepped after the copy, gives the same numbers (nothing shared)."""
    require("gym")
    import gymnasium as gym

    env = gym.make("lavendersim:ReactionWheelCube-v0", task=task, backend=backend, max_episode_steps=12,
                   dt=5e-3)     # 2 simulator steps per env step (the NumPy backend's Python loop)
    env.reset(seed=11)
    rng = np.random.default_rng(3)
    actions = rng.uniform(-1.5, 1.5, (45, 3)).astype(np.float32)    # some saturated; the corner task tips over
    _episodes(env, actions[:7])
    for name, make_copy in _copies().items():
        twin = make_copy(env)
        assert twin.unwrapped.sim is not env.unwrapped.sim
        ours = _episodes(twin, actions[7:])
        theirs = _episodes(copy.deepcopy(env) if name == "pickle" else pickle.loads(pickle.dumps(env)), actions[7:])
        assert ours == theirs
        assert len(ours) > len(actions[7:])     # at least one episode ended and started again from the generator
    assert _episodes(env, actions[7:]) == ours   # the original: the same numbers after its copies were taken
    twin.close()


def test_an_env_copied_before_its_first_reset_and_after_close():
    require("gym")
    from lavendersim.envs.reaction_wheel_cube import ReactionWheelCubeEnv

    env = ReactionWheelCubeEnv(render_mode="rgb_array")
    fresh = pickle.loads(pickle.dumps(env))
    assert _bits(fresh.reset(seed=4)) == _bits(env.reset(seed=4))
    assert env.render().shape == fresh.render().shape       # a drawn figure is not carried (drawn again)
    twin = copy.deepcopy(env)
    assert twin.render().shape[2] == 3 and _bits(twin.step(np.ones(3))) == _bits(env.step(np.ones(3)))
    env.close()
    assert pickle.loads(pickle.dumps(env)).sim is None


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_a_vector_env_pickles_and_deep_copies_bit_for_bit(backend):
    """The vector env's snapshot: its Sim (N cubes), per-cube generators, episode step counts, pending autoresets;
    the copy keeps the Sim's C fast path for one env step (Sim.fast_chunks)."""
    require("gym")
    import gymnasium as gym

    def make():
        return gym.make_vec("lavendersim:ReactionWheelCube-v0", num_envs=4, vectorization_mode="vector_entry_point",
                            task="corner", backend=backend, max_episode_steps=9, dt=5e-3)

    env = make()
    env.reset(seed=[5, None, 7, 8])
    rng = np.random.default_rng(8)
    actions = rng.uniform(-1.5, 1.5, (40, 4, 3)).astype(np.float32)
    _episodes(env, actions[:6], vector=True)
    for make_copy in _copies().values():
        twin = make_copy(env)
        assert twin.sim is not env.sim and twin._elapsed.tolist() == env._elapsed.tolist()
        if backend == "c":
            assert twin.sim._fast_n == env.sim._fast_n      # (white box: the copy keeps the one-call step)
        ours = _episodes(twin, actions[6:], vector=True)
        assert ours == _episodes(make_copy(env), actions[6:], vector=True)
    assert ours.count("ended") >= 2        # autoresets happened after the snapshot (truncation at 9 steps, tipped-over corners)
    assert _episodes(env, actions[6:], vector=True) == ours


# ---- the executor: what cannot be sent is named before anything runs; what fails in a worker arrives as itself ---

def _diverging(task):
    """A task function: a Sim stepped past its validity bound (DivergenceError) unless omega_y is small."""
    omega_y, dt, marker = task
    if marker:
        open(marker, "w").close()
    sc = lv.Scene()
    sc.add_body(lv.Body("b", 1.0, [1.0, 2.0, 3.0], omega_b=[0.0, omega_y, 0.1]))
    sim = lv.Sim(sc, dt=dt, integrator="euler")
    sim.run(50)
    return sim.x.copy()


class _Unsendable(Exception):
    """An exception that pickles but does not unpickle (its __init__ takes two arguments, args holds one)."""

    def __init__(self, a, b):
        super().__init__(f"{a} and {b}")


def _raise_unsendable(task):
    raise _Unsendable(task, 2)


def _return_a_lock(task):
    return threading.Lock()


class _HoldsALock:
    def __init__(self):
        self.lock = threading.Lock()


def _executors():
    """Local processes, and (distributed installed) a dask executor on a 1-worker LocalCluster."""
    yield X.Executor(X.PROCESSES, 2)
    if have("distributed"):
        from dask.distributed import LocalCluster

        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            yield X.resolve(dask=cluster.scheduler_address)


def test_a_task_that_diverges_reports_that_divergence(tmp_path):
    """The first diverging task in task order arrives as a DivergenceError with the fields a serial run gives (never
    BrokenProcessPool), the worker's traceback as its cause."""
    tasks = [(0.5, 0.05, None), (40.0, 0.05, None), (60.0, 0.05, None), (0.3, 0.05, None)]
    with pytest.raises(DivergenceError) as serial:
        X.map_tasks(_diverging, tasks)
    want = _fields(serial.value)
    kinds = []
    for ex in _executors():
        kinds.append(ex.kind)
        with pytest.raises(DivergenceError) as ei:
            ex.map(_diverging, tasks)
        assert _fields(ei.value) == want
        assert "Traceback" in str(ei.value.__cause__) and "_diverging" in str(ei.value.__cause__)
        good = ex.map(_diverging, [tasks[0], tasks[3]])       # the executor still works after a failure
        assert all(np.array_equal(a, b) for a, b in zip(good, X.map_tasks(_diverging, [tasks[0], tasks[3]])))
    assert kinds == ([X.PROCESSES, X.DASK] if have("distributed") else [X.PROCESSES])


def test_a_task_that_does_not_pickle_is_named_before_anything_runs(tmp_path):
    marker = str(tmp_path / "ran")
    cases = [("fn", lambda t: t, [(0.5, 0.05, marker)] * 2),
             ("tasks[1]", _diverging, [(0.5, 0.05, marker), (threading.Lock(), 0.05, marker)]),
             ("tasks[2]", _diverging, [(0.5, 0.05, marker)] * 2 + [_HoldsALock()])]
    for ex in _executors():
        for field, fn, tasks in cases:
            if field == "fn" and ex.kind == X.DASK:
                assert len(ex.map(fn, [1, 2])) == 2       # Dask sends functions with cloudpickle: a lambda is fine
                continue
            with pytest.raises(X.UnpicklableTaskError) as ei:
                ex.map(fn, tasks)
            e = ei.value
            assert isinstance(e, LavenderInputError) and isinstance(e, TypeError) and e.field == field
            assert ("lock" in e.detail) if field != "fn" else ("lambda" in e.detail)
            assert not (tmp_path / "ran").exists()       # refused before any task ran


def test_what_cannot_come_back_is_a_worker_error_naming_the_task():
    for ex in _executors():
        with pytest.raises(X.WorkerError, match=r"tasks\[0\]: _raise_unsendable raised .*_Unsendable: 1 and 2") as ei:
            ex.map(_raise_unsendable, [1, 3])
        assert "_raise_unsendable" in str(ei.value.__cause__)     # the worker's traceback
        with pytest.raises(X.WorkerError, match=r"tasks\[0\]: _return_a_lock returned a lock"):
            ex.map(_return_a_lock, [1, 3])
